// Every field of a completion the renderer uses is checked; each bad value is rejected with its name.
#include <gtest/gtest.h>

#include "../support/memory_page_file.hpp"
#include "texstream/protocol/completion_check.hpp"

namespace texstream {
namespace {

CompletionRecord good_record() {
  CompletionRecord r{};
  r.status = static_cast<uint32_t>(CompletionStatus::kOk);
  r.request_kind = static_cast<uint32_t>(RequestKind::kLoad);
  r.slot = 2;
  r.texture_id = 7;
  r.mip_level = 1;
  r.generation = 5;
  r.format = static_cast<uint32_t>(TexelFormat::kRgba8);
  r.width = 64;
  r.height = 16;
  r.byte_size = 64 * 16 * 4;
  return r;
}

const TextureShape kShape{128, 32, full_mip_count(128, 32), TexelFormat::kRgba8};

void expect_rejected(const CompletionRecord& r, const char* field) {
  auto c = check_completion(r, 4, 1 << 20);
  if (c.ok()) {
    const Status st = check_against_texture(c.value(), kShape);
    ASSERT_FALSE(st.ok()) << "accepted a record with a bad " << field;
    EXPECT_NE(st.error().message.find(field), std::string::npos) << st.error().message;
  } else {
    EXPECT_NE(c.error().message.find(field), std::string::npos) << c.error().message;
  }
}

TEST(CompletionCheck, AcceptsAConsistentRecord) {
  auto c = check_completion(good_record(), 4, 1 << 20);
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_TRUE(check_against_texture(c.value(), kShape).ok());
  EXPECT_EQ(c->slot.value, 2u);
  EXPECT_EQ(c->extent, (Extent2D{64, 16}));
}

TEST(CompletionCheck, RejectsEachBadField) {
  CompletionRecord r = good_record();
  r.status = 0;
  expect_rejected(r, "status");
  r = good_record();
  r.status = 99;
  expect_rejected(r, "status");
  r = good_record();
  r.slot = 4;  // == slot_count
  expect_rejected(r, "slot");
  r = good_record();
  r.slot = kNoSlot;
  expect_rejected(r, "slot");
  r = good_record();
  r.byte_size = (1 << 20) + 1;  // larger than a slot
  expect_rejected(r, "byte_size");
  r = good_record();
  r.byte_size = 0;
  expect_rejected(r, "byte_size");
  r = good_record();
  r.byte_size = 64 * 16 * 4 - 4;  // fits a slot, but is not this mip's size
  expect_rejected(r, "byte_size");
  r = good_record();
  r.format = 77;
  expect_rejected(r, "format");
  r = good_record();
  r.format = static_cast<uint32_t>(TexelFormat::kBc1);
  expect_rejected(r, "format");
  r = good_record();
  r.mip_level = 8;  // 128x32 has 8 mips: 0..7
  expect_rejected(r, "mip_level");
  r = good_record();
  r.width = 0xffffffffu;
  expect_rejected(r, "width");
  r = good_record();
  r.width = 32;  // mip 1 of 128x32 is 64x16
  expect_rejected(r, "extent");
}

TEST(CompletionCheck, ErrorStatusesCarryNoSlot) {
  CompletionRecord r = good_record();
  r.status = static_cast<uint32_t>(CompletionStatus::kNotFound);
  EXPECT_FALSE(check_completion(r, 4, 1 << 20).ok()) << "a failed completion naming a slot would leak it";
  r.slot = kNoSlot;
  auto c = check_completion(r, 4, 1 << 20);
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(c->status, CompletionStatus::kNotFound);
}

TEST(CompletionCheck, RequestKindMustBeAMipOrAPage) {
  CompletionRecord r = good_record();
  r.request_kind = 0;
  expect_rejected(r, "request_kind");
  r.request_kind = static_cast<uint32_t>(RequestKind::kReleaseSlot);
  expect_rejected(r, "request_kind");
  r = good_record();
  r.page_x = 1;  // a mip's completion carries no page position
  expect_rejected(r, "page_x");
}

CompletionRecord good_page_record() {
  CompletionRecord r{};
  r.status = static_cast<uint32_t>(CompletionStatus::kOk);
  r.request_kind = static_cast<uint32_t>(RequestKind::kLoadPage);
  r.slot = 1;
  r.texture_id = 0;  // the page file
  r.mip_level = 0;   // the root's level
  r.generation = 3;
  r.format = static_cast<uint32_t>(TexelFormat::kRgba8);
  r.width = 8;
  r.height = 8;
  r.byte_size = 256;
  return r;
}

void expect_page_rejected(const pages::PageFile& file, const CompletionRecord& r, const char* field) {
  auto c = check_completion(r, 4, 1 << 20);
  if (c.ok()) {
    const Status st = check_against_page_file(c.value(), file);
    ASSERT_FALSE(st.ok()) << "accepted a page record with a bad " << field;
    EXPECT_NE(st.error().message.find(field), std::string::npos) << st.error().message;
  } else {
    EXPECT_NE(c.error().message.find(field), std::string::npos) << c.error().message;
  }
}

TEST(CompletionCheck, PageRecordIsCheckedAgainstThePageFile) {
  const test::MemoryPageFile memory(1);  // the root page only, 8x8 RGBA8 (256 bytes)
  ASSERT_NE(memory.file, nullptr);
  const pages::PageFile& file = *memory.file;
  auto c = check_completion(good_page_record(), 4, 1 << 20);
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->kind, RequestKind::kLoadPage);
  EXPECT_EQ(c->page_file, 0u);
  EXPECT_EQ(c->page, (pages::PageId{0, 0, 0}));
  EXPECT_TRUE(check_against_page_file(*c, file).ok());
  // A page is never a mip, nor a mip a page.
  EXPECT_FALSE(check_against_texture(*c, kShape).ok());
  auto mip = check_completion(good_record(), 4, 1 << 20);
  ASSERT_TRUE(mip.ok());
  EXPECT_FALSE(check_against_page_file(*mip, file).ok());

  CompletionRecord r = good_page_record();
  r.byte_size = 252;
  expect_page_rejected(file, r, "byte_size");
  r = good_page_record();
  r.format = static_cast<uint32_t>(TexelFormat::kBc1);
  expect_page_rejected(file, r, "format");
  r = good_page_record();
  r.width = 16;
  expect_page_rejected(file, r, "extent");
  r = good_page_record();
  r.page_x = 1;  // level 0 has one page
  expect_page_rejected(file, r, "not stored");
  r = good_page_record();
  r.mip_level = 1;  // the file has one level
  expect_page_rejected(file, r, "not stored");
}

TEST(TexelFormat, MipArithmetic) {
  EXPECT_EQ(full_mip_count(512, 4), 10u);
  EXPECT_EQ(full_mip_count(1, 1), 1u);
  EXPECT_EQ(mip_extent(512, 4, 3), (Extent2D{64, 1}));
  EXPECT_EQ(mip_bytes(TexelFormat::kRgba8, 8, 4, 0), 128u);
  // BC1 rounds up to whole 4x4 blocks of 8 bytes: a 2x1 mip is one block.
  EXPECT_EQ(mip_bytes(TexelFormat::kBc1, Extent2D{2, 1}), 8u);
  EXPECT_EQ(mip_bytes(TexelFormat::kBc1, Extent2D{8, 4}), 16u);
  EXPECT_EQ(mip_chain_offset(TexelFormat::kRgba8, 4, 4, 2), 64u + 16u);
}

}  // namespace
}  // namespace texstream
