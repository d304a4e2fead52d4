#pragma once
// The renderer's first line of defence: a CompletionRecord copied out of the ring is checked field by field
// before anything in it is used. The texture-specific checks (id in range, mip extent and byte size equal to
// what the scene's texture table implies) need the texture table and are done by `check_against_texture`.
#include <cstdint>

#include "texstream/common/ids.hpp"
#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"
#include "texstream/protocol/records.hpp"

namespace texstream {

struct CheckedCompletion {
  CompletionStatus status;
  TextureId texture;
  MipLevel mip;
  Generation generation;
  SlotIndex slot;      // valid only for kOk
  uint64_t byte_size;  // kOk: <= slot_bytes
  TexelFormat format;  // kOk only
  Extent2D extent;     // kOk only
  uint64_t checksum;
};

// Structural checks: status known; for kOk a slot < slot_count, a byte size in (0, slot_bytes], a known
// format, an extent within kMaxTextureExtent; for other statuses no slot.
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

}  // namespace texstream
