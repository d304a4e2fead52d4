// libFuzzer: completion validation. Input = a CompletionRecord (64 bytes), the segment's slot count and size,
// and a texture shape. Invariants: a record that passes check_completion names a slot in range with a size
// that fits it; one that also passes check_against_texture is a mip's with exactly the mip's size and extent;
// one that passes check_against_page_file (a two-level page file in memory) is a page's, stored, with exactly
// its index entry's size, the file's format and side.
#include <cstdint>
#include <cstring>

#include "../support/memory_page_file.hpp"
#include "texstream/protocol/completion_check.hpp"

using namespace texstream;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  struct Input {
    CompletionRecord record;
    uint32_t slot_count;
    uint32_t slot_bytes_kib;
    uint32_t width, height, mip_count, format;
  } in{};
  if (size < sizeof in) return 0;
  std::memcpy(&in, data, sizeof in);
  const uint32_t slot_count = 1u + in.slot_count % 16384;
  const uint64_t slot_bytes = (1u + in.slot_bytes_kib % 65536) * uint64_t{1024};
  auto c = check_completion(in.record, slot_count, slot_bytes);
  if (!c) return 0;
  if (c->status == CompletionStatus::kOk) {
    if (c->slot.value >= slot_count || c->byte_size > slot_bytes) __builtin_trap();
  }
  const TextureShape shape{1u + in.width % 16384, 1u + in.height % 16384, 1u + in.mip_count % 16,
                           static_cast<TexelFormat>(in.format % 4)};
  if (check_against_texture(*c, shape).ok() && c->status == CompletionStatus::kOk) {
    if (c->kind != RequestKind::kLoad) __builtin_trap();
    if (c->mip.value >= shape.mip_count) __builtin_trap();
    if (c->byte_size != mip_bytes(shape.format, shape.width, shape.height, c->mip.value)) __builtin_trap();
  }
  static const test::MemoryPageFile pages(2);   // the root and its 4 children, 8x8 RGBA8, 256 bytes each
  if (pages.file == nullptr) __builtin_trap();  // a harness bug
  if (check_against_page_file(*c, *pages.file).ok() && c->status == CompletionStatus::kOk) {
    if (c->kind != RequestKind::kLoadPage || !pages.file->stored(c->page)) __builtin_trap();
    if (c->byte_size != 256 || c->format != TexelFormat::kRgba8 || c->extent != Extent2D{8, 8}) __builtin_trap();
  }
  return 0;
}
