#pragma once
// Texel formats on the wire and on disk, and the mip arithmetic both processes must agree on: the server
// computes where a mip lies and how large it is; the renderer re-computes the same to validate a completion.
#include <algorithm>
#include <bit>
#include <cstdint>
#include <optional>
#include <string_view>

namespace texstream {

enum class TexelFormat : uint32_t {
  kRgba8 = 1,  // 4 bytes per texel, sRGB-encoded colour
  kBc1 = 2,    // 8 bytes per 4x4 block (seed 000 Table 1: the city datasets are BC1)
  kBc3 = 3,    // 16 bytes per 4x4 block (DXT5): a BC1 colour block and an 8-bit alpha block
  kBc7 = 4,    // 16 bytes per 4x4 block: served raw from DDS files with the DX10 extension (no encoder here)
};

constexpr bool is_block_compressed(TexelFormat f) {
  return f == TexelFormat::kBc1 || f == TexelFormat::kBc3 || f == TexelFormat::kBc7;
}
// Bytes of one 4x4 block of a block-compressed format.
constexpr uint64_t block_bytes(TexelFormat f) { return f == TexelFormat::kBc1 ? 8 : 16; }

constexpr std::optional<TexelFormat> texel_format_from_raw(uint32_t raw) {
  if (raw == static_cast<uint32_t>(TexelFormat::kRgba8)) return TexelFormat::kRgba8;
  if (raw == static_cast<uint32_t>(TexelFormat::kBc1)) return TexelFormat::kBc1;
  if (raw == static_cast<uint32_t>(TexelFormat::kBc3)) return TexelFormat::kBc3;
  if (raw == static_cast<uint32_t>(TexelFormat::kBc7)) return TexelFormat::kBc7;
  return std::nullopt;
}

constexpr std::string_view to_string(TexelFormat f) {
  return f == TexelFormat::kRgba8 ? "rgba8"
         : f == TexelFormat::kBc1 ? "bc1"
         : f == TexelFormat::kBc3 ? "bc3"
         : f == TexelFormat::kBc7 ? "bc7"
                                  : "?";
}

constexpr std::optional<TexelFormat> texel_format_from_string(std::string_view s) {
  if (s == "rgba8") return TexelFormat::kRgba8;
  if (s == "bc1") return TexelFormat::kBc1;
  if (s == "bc3") return TexelFormat::kBc3;
  if (s == "bc7") return TexelFormat::kBc7;
  return std::nullopt;
}

// Largest texture extent we accept (2^15): bounds every size computation below far from overflow.
inline constexpr uint32_t kMaxTextureExtent = 1u << 15;

constexpr uint32_t floor_log2(uint32_t v) { return v == 0 ? 0 : 31u - static_cast<uint32_t>(__builtin_clz(v)); }

// Full mip chain down to 1x1: levels = floor(log2(max(w, h))) + 1.
constexpr uint32_t full_mip_count(uint32_t width, uint32_t height) { return floor_log2(std::max(width, height)) + 1; }

struct Extent2D {
  uint32_t width;
  uint32_t height;
  constexpr bool operator==(const Extent2D&) const = default;
};

// The levels a texture is sampled from, given the mask of its resident levels (bit L: level L; levels are below
// 32): the run of resident levels that ends at the coarsest one. A sparse image has no holes the sampler could
// skip, so a finer level resident beyond a gap is not drawn until the gap is filled. `mask` != 0.
struct MipRun {
  uint32_t finest;
  uint32_t coarsest;
};
constexpr MipRun sampled_run(uint32_t mask) {
  const uint32_t coarsest = 31u - static_cast<uint32_t>(std::countl_zero(mask));
  uint32_t finest = coarsest;
  while (finest > 0 && (mask & (1u << (finest - 1)))) --finest;
  return {finest, coarsest};
}

constexpr Extent2D mip_extent(uint32_t width, uint32_t height, uint32_t level) {
  return {std::max(1u, width >> level), std::max(1u, height >> level)};
}

// Bytes of one mip level. BC1/BC3/BC7 round each side up to whole 4x4 blocks (a 1x1 BC1 mip is one 8-byte block).
constexpr uint64_t mip_bytes(TexelFormat format, Extent2D e) {
  if (is_block_compressed(format)) {
    const uint64_t bw = (e.width + 3) / 4, bh = (e.height + 3) / 4;
    return bw * bh * block_bytes(format);
  }
  return uint64_t{e.width} * e.height * 4;
}

constexpr uint64_t mip_bytes(TexelFormat format, uint32_t width, uint32_t height, uint32_t level) {
  return mip_bytes(format, mip_extent(width, height, level));
}

// Bytes of levels [0, level): the offset of `level` in a file that stores mips finest first, back to back.
constexpr uint64_t mip_chain_offset(TexelFormat format, uint32_t width, uint32_t height, uint32_t level) {
  uint64_t offset = 0;
  for (uint32_t l = 0; l < level; ++l) offset += mip_bytes(format, width, height, l);
  return offset;
}

constexpr bool valid_texture_extent(uint32_t width, uint32_t height) {
  return width >= 1 && height >= 1 && width <= kMaxTextureExtent && height <= kMaxTextureExtent;
}

}  // namespace texstream
