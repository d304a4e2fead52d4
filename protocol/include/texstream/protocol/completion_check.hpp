#pragma once
// The renderer's first line of defence: a CompletionRecord copied out of the ring is checked field by field
// before anything in it is used. The texture-specific checks (id in range, mip extent and byte size equal to
// what the scene's texture table implies) need the texture table and are done by `check_against_texture`; a
// page's (stored, byte size, format and side those of the page file) need the page file's index and are done
// by `check_against_page_file`.
#include <cstdint>

#include "texstream/common/ids.hpp"
#include "texstream/common/page_file.hpp"
#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"
#include "texstream/protocol/records.hpp"

namespace texstream {

struct CheckedCompletion {
  CompletionStatus status;
  RequestKind kind;    // kLoad (a mip) or kLoadPage (a page)
  TextureId texture;   // kLoad
  MipLevel mip;        // kLoad
  uint32_t page_file;  // kLoadPage: the page file's index
  pages::PageId page;  // kLoadPage (level from mip_level)
  Generation generation;
  SlotIndex slot;      // valid only for kOk
  uint64_t byte_size;  // kOk: <= slot_bytes
  TexelFormat format;  // kOk only
  Extent2D extent;     // kOk only
  uint64_t checksum;
};

// Structural checks: status known; request_kind kLoad or kLoadPage (page_x, page_y 0 for kLoad); for kOk a
// slot < slot_count, a byte size in (0, slot_bytes], a known format, an extent within kMaxTextureExtent; for
// other statuses no slot.
Result<CheckedCompletion> check_completion(const CompletionRecord& record, uint32_t slot_count, uint64_t slot_bytes);

// What the renderer knows about a texture from the scene's texture table.
struct TextureShape {
  uint32_t width;
  uint32_t height;
  uint32_t mip_count;
  TexelFormat format;
};

// Semantic checks of a kOk completion against the texture it claims: mip < mip_count, extent and byte size
// exactly those of that mip, same format.
Status check_against_texture(const CheckedCompletion& c, const TextureShape& shape);

// Semantic checks of a kOk page completion against the page file it names (the renderer's own copy of its
// index): the page inside the quadtree and stored, byte size that of its index entry, the file's format, a
// square of the file's stored side (page_texels + 2 borders).
Status check_against_page_file(const CheckedCompletion& c, const pages::PageFile& file);

}  // namespace texstream
