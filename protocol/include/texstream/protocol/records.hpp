#pragma once
// The records that cross the rings. They are part of the segment ABI: fixed size, explicit padding, offsets
// pinned by static_asserts here and again by tests/unit/protocol_layout_test.cpp. A change of any of them
// bumps kLayoutVersion in segment_layout.hpp.
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "texstream/common/ids.hpp"
#include "texstream/common/page_file.hpp"

namespace texstream {

inline constexpr uint32_t kNoSlot = 0xffffffffu;

enum class RequestKind : uint32_t {
  kLoad = 1,         // load mip `mip_level` of `texture_id` into a staging slot
  kReleaseSlot = 2,  // the renderer is done with `slot`: ownership goes back to the server
  // load page (mip_level, page_x, page_y) of page file `texture_id` (an index: 0 = the scene manifest's
  // "ground"; page_file.hpp) into a staging slot, exactly the bytes the file stores for it
  kLoadPage = 3,
};

// renderer → server. 64 bytes, one cache line.
struct RequestRecord {
  uint32_t kind;        // RequestKind
  uint32_t texture_id;  // kLoad: the texture; kLoadPage: the page file's index
  uint32_t mip_level;   // kLoad: 0 = full resolution; kLoadPage: the page's level (0 = the root, coarsest)
  uint32_t slot;        // kReleaseSlot
  uint64_t generation;  // streaming cycle that asked; a newer one supersedes requests not yet started
  float priority;       // larger = sooner (seed 000 Eq. 1 mesh weight)
  uint32_t page_x;      // kLoadPage: the page's column in its level (PageId::x)
  uint32_t page_y;      // kLoadPage: the page's row in its level (PageId::y)
  uint32_t reserved0;
  uint64_t reserved1[3];
};
static_assert(std::is_trivially_copyable_v<RequestRecord> && std::is_standard_layout_v<RequestRecord>);
static_assert(sizeof(RequestRecord) == 64 && alignof(RequestRecord) == 8);
static_assert(offsetof(RequestRecord, kind) == 0);
static_assert(offsetof(RequestRecord, texture_id) == 4);
static_assert(offsetof(RequestRecord, mip_level) == 8);
static_assert(offsetof(RequestRecord, slot) == 12);
static_assert(offsetof(RequestRecord, generation) == 16);
static_assert(offsetof(RequestRecord, priority) == 24);
static_assert(offsetof(RequestRecord, page_x) == 28);
static_assert(offsetof(RequestRecord, page_y) == 32);
static_assert(offsetof(RequestRecord, reserved0) == 36);
static_assert(offsetof(RequestRecord, reserved1) == 40);

enum class CompletionStatus : uint32_t {
  kOk = 1,         // payload in `slot`
  kNotFound = 2,   // no such texture or file
  kCorrupt = 3,    // the file does not match its header / index, or is truncated
  kTimedOut = 4,   // storage did not answer in time
  kCancelled = 5,  // superseded by a newer generation before it started
  kIoError = 6,    // any other read failure
  kUnfilled = 7,   // could not be served now (no free slot, busy origin): ask again later (seed 002 §4.3)
};
inline constexpr uint32_t kMaxCompletionStatus = 7;

// server → renderer. 64 bytes. Everything in it is untrusted until the renderer has validated its copy.
// texture_id, mip_level, generation, request_kind and (for a page) page_x, page_y echo the request answered.
struct CompletionRecord {
  uint32_t status;      // CompletionStatus
  uint32_t slot;        // kOk: staging slot holding the payload; otherwise kNoSlot
  uint32_t texture_id;  // a mip's texture, or a page's file index
  uint32_t mip_level;   // a mip's level, or a page's level
  uint64_t generation;  // echoed from the request
  uint64_t byte_size;   // payload bytes at the start of the slot
  uint32_t format;      // TexelFormat
  uint32_t width;       // texels of this mip, or of the page with its borders (page_texels + 2 borders)
  uint32_t height;
  uint32_t request_kind;  // RequestKind::kLoad (a mip) or kLoadPage (a page): what is answered
  uint64_t checksum;      // XXH3-64 of the payload bytes
  uint32_t page_x;        // kLoadPage: the page's column; 0 for a mip
  uint32_t page_y;        // kLoadPage: the page's row; 0 for a mip
};
static_assert(std::is_trivially_copyable_v<CompletionRecord> && std::is_standard_layout_v<CompletionRecord>);
static_assert(sizeof(CompletionRecord) == 64 && alignof(CompletionRecord) == 8);
static_assert(offsetof(CompletionRecord, status) == 0);
static_assert(offsetof(CompletionRecord, slot) == 4);
static_assert(offsetof(CompletionRecord, texture_id) == 8);
static_assert(offsetof(CompletionRecord, mip_level) == 12);
static_assert(offsetof(CompletionRecord, generation) == 16);
static_assert(offsetof(CompletionRecord, byte_size) == 24);
static_assert(offsetof(CompletionRecord, format) == 32);
static_assert(offsetof(CompletionRecord, width) == 36);
static_assert(offsetof(CompletionRecord, height) == 40);
static_assert(offsetof(CompletionRecord, request_kind) == 44);
static_assert(offsetof(CompletionRecord, checksum) == 48);
static_assert(offsetof(CompletionRecord, page_x) == 56);
static_assert(offsetof(CompletionRecord, page_y) == 60);

const char* to_string(CompletionStatus status);

// The requests the renderer sends, built in one place (RendererEndpoint pushes them).
inline RequestRecord make_load_request(TextureId texture, MipLevel mip, Generation generation, float priority) {
  RequestRecord r{};
  r.kind = static_cast<uint32_t>(RequestKind::kLoad);
  r.texture_id = texture.value;
  r.mip_level = mip.value;
  r.slot = kNoSlot;
  r.generation = generation.value;
  r.priority = priority;
  return r;
}
// `file`: the page file's index (0 = the scene's ground).
inline RequestRecord make_load_page_request(uint32_t file, pages::PageId page, Generation generation, float priority) {
  RequestRecord r{};
  r.kind = static_cast<uint32_t>(RequestKind::kLoadPage);
  r.texture_id = file;
  r.mip_level = page.level;
  r.page_x = page.x;
  r.page_y = page.y;
  r.slot = kNoSlot;
  r.generation = generation.value;
  r.priority = priority;
  return r;
}
inline RequestRecord make_release_request(SlotIndex slot, Generation generation) {
  RequestRecord r{};
  r.kind = static_cast<uint32_t>(RequestKind::kReleaseSlot);
  r.slot = slot.value;
  r.generation = generation.value;
  return r;
}

}  // namespace texstream
