// Pins the segment ABI a second time, from outside the headers: a change to any offset or size fails here
// and must come with a kLayoutVersion bump.
#include <gtest/gtest.h>

#include <boost/version.hpp>
#include <cstring>

#include "texstream/protocol/records.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/protocol/segment_layout.hpp"

namespace texstream {
namespace {

TEST(ProtocolLayout, RecordSizesAndOffsets) {
  EXPECT_EQ(sizeof(RequestRecord), 64u);
  EXPECT_EQ(offsetof(RequestRecord, generation), 16u);
  EXPECT_EQ(offsetof(RequestRecord, priority), 24u);
  EXPECT_EQ(sizeof(CompletionRecord), 64u);
  EXPECT_EQ(offsetof(CompletionRecord, byte_size), 24u);
  EXPECT_EQ(offsetof(CompletionRecord, checksum), 48u);
  EXPECT_EQ(sizeof(SegmentHeader), 224u);
  EXPECT_EQ(sizeof(RendererBlock), 64u);
  EXPECT_EQ(sizeof(ServerBlock), 128u);
  EXPECT_EQ(offsetof(ServerBlock, loading), 80u);  // version 2: the load workers' textures (crash quarantine)
  EXPECT_EQ(kLoadingWords, 8u);
  EXPECT_EQ(sizeof(RingControl), 128u);
  EXPECT_EQ(offsetof(RingControl, read_pos), 64u);
  EXPECT_EQ(offsetof(SegmentHeader, texture_count), 160u);  // version 3: the renderer's texture table
  EXPECT_EQ(offsetof(SegmentHeader, texture_table_fingerprint), 168u);
  EXPECT_EQ(offsetof(RendererBlock, waiting), 36u);  // version 4: the completion bell
  EXPECT_EQ(offsetof(ServerBlock, syscalls), 112u);
  EXPECT_EQ(offsetof(ServerBlock, completion_bell), 120u);
  // version 5: page requests (RequestKind::kLoadPage) in what were reserved fields; the records stay 64 bytes
  EXPECT_EQ(static_cast<uint32_t>(RequestKind::kLoadPage), 3u);
  EXPECT_EQ(offsetof(RequestRecord, page_x), 28u);
  EXPECT_EQ(offsetof(RequestRecord, page_y), 32u);
  EXPECT_EQ(offsetof(RequestRecord, reserved0), 36u);
  EXPECT_EQ(offsetof(RequestRecord, reserved1), 40u);
  EXPECT_EQ(offsetof(CompletionRecord, request_kind), 44u);
  EXPECT_EQ(offsetof(CompletionRecord, page_x), 56u);
  EXPECT_EQ(offsetof(CompletionRecord, page_y), 60u);
  EXPECT_EQ(kLayoutVersion, 5u);
}

TEST(ProtocolLayout, ComputedLayoutIsAlignedAndDisjoint) {
  const SegmentParams p{1024, 1024, 32, 1 << 20};
  const SegmentLayout l = compute_layout(p);
  EXPECT_EQ(l.renderer_block_offset, kSegmentHeaderBytes);
  EXPECT_GE(l.server_block_offset, l.renderer_block_offset + sizeof(RendererBlock));
  EXPECT_EQ(l.request_ring_offset % 128, 0u);
  EXPECT_GE(l.completion_ring_offset, l.request_ring_offset + sizeof(RingControl) + 1024 * sizeof(RequestRecord));
  EXPECT_EQ(l.slots_offset % kSlotAlignment, 0u);
  EXPECT_GE(l.slots_offset, l.completion_ring_offset + sizeof(RingControl) + 1024 * sizeof(CompletionRecord));
  EXPECT_EQ(l.total_bytes, l.slots_offset + 32ull * (1 << 20));
  // An odd slot size is rounded up to whole pages so every slot starts page-aligned.
  EXPECT_EQ(compute_layout({4, 4, 3, 5000}).slot_bytes, 8192u);
}

TEST(ProtocolLayout, RecordRoundTripThroughBytes) {
  RequestRecord r{};
  r.kind = static_cast<uint32_t>(RequestKind::kLoad);
  r.texture_id = 123456;
  r.mip_level = 7;
  r.generation = 0x0102030405060708ull;
  r.priority = 1234.5f;
  unsigned char bytes[sizeof r];
  std::memcpy(bytes, &r, sizeof r);
  // Little-endian wire: the generation's low byte sits at offset 16.
  EXPECT_EQ(bytes[16], 0x08);
  RequestRecord back{};
  std::memcpy(&back, bytes, sizeof back);
  EXPECT_EQ(back.texture_id, 123456u);
  EXPECT_EQ(back.mip_level, 7u);
  EXPECT_EQ(back.generation, r.generation);
  EXPECT_EQ(back.priority, 1234.5f);

  CompletionRecord c{};
  c.status = static_cast<uint32_t>(CompletionStatus::kOk);
  c.slot = 3;
  c.byte_size = 65536;
  c.checksum = 0xdeadbeefcafef00dull;
  unsigned char cb[sizeof c];
  std::memcpy(cb, &c, sizeof c);
  CompletionRecord cback{};
  std::memcpy(&cback, cb, sizeof cback);
  EXPECT_EQ(cback.slot, 3u);
  EXPECT_EQ(cback.byte_size, 65536u);
  EXPECT_EQ(cback.checksum, c.checksum);
}

TEST(ProtocolLayout, PageRequestCarriesFileLevelAndPosition) {
  const RequestRecord r = make_load_page_request(0, pages::PageId{5, 17, 31}, Generation(9), 2.5f);
  unsigned char bytes[sizeof r];
  std::memcpy(bytes, &r, sizeof r);
  uint32_t word = 0;
  std::memcpy(&word, bytes + 0, 4);
  EXPECT_EQ(word, 3u);  // kind
  std::memcpy(&word, bytes + 8, 4);
  EXPECT_EQ(word, 5u);  // level in mip_level
  std::memcpy(&word, bytes + 12, 4);
  EXPECT_EQ(word, kNoSlot);
  std::memcpy(&word, bytes + 28, 4);
  EXPECT_EQ(word, 17u);  // x
  std::memcpy(&word, bytes + 32, 4);
  EXPECT_EQ(word, 31u);  // y
  EXPECT_EQ(r.texture_id, 0u);
  EXPECT_EQ(r.generation, 9u);
  EXPECT_EQ(r.priority, 2.5f);
  // The reserved words stay zero.
  for (size_t i = 36; i < sizeof r; ++i) EXPECT_EQ(bytes[i], 0) << i;
}

TEST(ProtocolLayout, HeaderValidationNamesTheField) {
  const SegmentParams p{64, 64, 4, 1 << 16};
  const SegmentHeader good = make_header(p, 42);
  const uint64_t mapped = compute_layout(p).total_bytes;
  EXPECT_TRUE(validate_header(good, mapped).ok());

  auto expect_field = [&](SegmentHeader h, const char* field) {
    const Status st = validate_header(h, mapped);
    ASSERT_FALSE(st.ok()) << field;
    EXPECT_NE(st.error().message.find(std::string("'") + field + "'"), std::string::npos) << st.error().message;
  };
  SegmentHeader h = good;
  h.magic ^= 1;
  expect_field(h, "magic");
  h = good;
  h.layout_version = 99;
  expect_field(h, "layout_version");
  h = good;
  h.boost_version = BOOST_VERSION + 100;
  expect_field(h, "boost_version");
  h = good;
  h.compiler[0] = 'X';
  expect_field(h, "compiler");
  h = good;
  h.request_capacity = 48;  // not a power of two
  expect_field(h, "request_capacity");
  h = good;
  h.slot_count = 0;
  expect_field(h, "slot_count");
  h = good;
  h.slots_offset += 4096;  // a region moved elsewhere
  expect_field(h, "slots_offset");
  h = good;
  h.slot_count = 8;  // claims more slots than are mapped
  h.segment_bytes = compute_layout({64, 64, 8, 1 << 16}).total_bytes;
  expect_field(h, "segment_bytes");
}

}  // namespace
}  // namespace texstream
