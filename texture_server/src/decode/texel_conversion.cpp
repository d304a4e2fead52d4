#include "texstream/server/decode/texel_conversion.hpp"

#include <algorithm>
#include <cmath>

namespace texstream::server {

namespace {

uint8_t unit_to_u8(float v) {
  if (!(v > 0.0f)) return 0;  // also NaN
  if (v >= 1.0f) return 255;
  return static_cast<uint8_t>(std::lround(v * 255.0f));
}

template <class T, class Colour, class Alpha>
void expand(const T* src, uint32_t channels, size_t pixels, std::byte* out, Colour colour, Alpha alpha) {
  for (size_t i = 0; i < pixels; ++i, src += channels, out += 4) {
    uint8_t r, g, b, a;
    if (channels <= 2) {
      r = g = b = colour(src[0]);
      a = channels == 2 ? alpha(src[1]) : 255;
    } else {
      r = colour(src[0]);
      g = colour(src[1]);
      b = colour(src[2]);
      a = channels >= 4 ? alpha(src[3]) : 255;
    }
    out[0] = std::byte{r};
    out[1] = std::byte{g};
    out[2] = std::byte{b};
    out[3] = std::byte{a};
  }
}

}  // namespace

uint8_t linear_to_srgb8(float linear) {
  if (!(linear > 0.0f)) return 0;
  if (linear >= 1.0f) return 255;
  const float s = linear <= 0.0031308f ? 12.92f * linear : 1.055f * std::pow(linear, 1.0f / 2.4f) - 0.055f;
  return unit_to_u8(s);
}

void channels_u8_to_rgba8(const uint8_t* src, uint32_t channels, size_t pixels, std::byte* out) {
  const auto same = [](uint8_t v) { return v; };
  expand(src, std::max(channels, 1u), pixels, out, same, same);
}

void channels_linear_float_to_rgba8(const float* src, uint32_t channels, size_t pixels, std::byte* out) {
  expand(src, std::max(channels, 1u), pixels, out, linear_to_srgb8, unit_to_u8);
}

}  // namespace texstream::server
