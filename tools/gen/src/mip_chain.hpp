#pragma once
// The full mip chain of an RGBA8 image, each level a box filter of the previous one in linear light
// (sRGB decoded, averaged, re-encoded): averaging sRGB values directly would darken every coarser mip.
#include <cstdint>
#include <span>
#include <vector>

namespace texstream::gen {

// Levels 1 .. full_mip_count - 1 of `mip0` (width x height, R in the low byte), written after it into
// `chain`, which must hold mip_chain_offset(kRgba8, w, h, full_mip_count) / 4 texels and begin with mip0.
// Any extent works: a side of 1 stays 1, an odd side's last output texel also covers the leftover input.
void build_mip_chain(uint32_t width, uint32_t height, std::span<uint32_t> chain);

// One level: `dst` (dw x dh) from `src` (sw x sh), dw = max(1, sw / 2), dh = max(1, sh / 2).
void downsample_linear(const uint32_t* src, uint32_t sw, uint32_t sh, uint32_t* dst, uint32_t dw, uint32_t dh);

// Exact sRGB conversions of 8-bit values, shared with tests.
float srgb8_to_linear(uint8_t v);
uint8_t linear_to_srgb8(float linear);

}  // namespace texstream::gen
