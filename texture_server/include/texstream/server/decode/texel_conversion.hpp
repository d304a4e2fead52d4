#pragma once
// Decoded pixels → the RGBA8 texels the renderer receives (TexelFormat::kRgba8: sRGB-encoded colour, linear
// alpha). Channel counts: 1 = grey, 2 = grey + alpha, 3 = RGB, 4 or more = RGBA (extra channels dropped).
// Missing alpha is opaque. Pure functions (unit-tested), no allocation.
#include <cstddef>
#include <cstdint>

namespace texstream::server {

// 8-bit channels (already sRGB-encoded, as 8-bit image files are) → RGBA8.
void channels_u8_to_rgba8(const uint8_t* src, uint32_t channels, size_t pixels, std::byte* out);
// Float channels in linear light (OpenEXR, half or float) → sRGB-encoded RGBA8; alpha stays linear.
// Values are clamped to [0, 1]; NaN becomes 0.
void channels_linear_float_to_rgba8(const float* src, uint32_t channels, size_t pixels, std::byte* out);
// The sRGB transfer function (IEC 61966-2-1) of one linear value in [0, 1], rounded to 8 bits.
uint8_t linear_to_srgb8(float linear);

}  // namespace texstream::server
