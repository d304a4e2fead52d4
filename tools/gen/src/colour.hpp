#pragma once
// Colours for painting: sRGB-encoded floats in [0, 1] (what the eye and the palette speak), and the exact
// sRGB transfer functions for filtering in linear light.
#include <algorithm>
#include <cmath>
#include <cstdint>

namespace texstream::gen {

struct Rgb {
  float r = 0, g = 0, b = 0;
};

inline Rgb operator*(Rgb c, float k) { return {c.r * k, c.g * k, c.b * k}; }
inline Rgb operator+(Rgb a, Rgb b) { return {a.r + b.r, a.g + b.g, a.b + b.b}; }
inline Rgb lerp(Rgb a, Rgb b, float t) { return {a.r + (b.r - a.r) * t, a.g + (b.g - a.g) * t, a.b + (b.b - a.b) * t}; }
inline Rgb rgb8(int r, int g, int b) {
  return {static_cast<float>(r) / 255.0f, static_cast<float>(g) / 255.0f, static_cast<float>(b) / 255.0f};
}

// Packs to RGBA8 with R in the low byte (the DDS masks of scene_format.hpp), alpha opaque.
inline uint32_t pack_rgba8(Rgb c) {
  const auto q = [](float v) { return static_cast<uint32_t>(std::clamp(v, 0.0f, 1.0f) * 255.0f + 0.5f); };
  return q(c.r) | (q(c.g) << 8) | (q(c.b) << 16) | 0xff000000u;
}

// HSV (all in [0, 1]) round trip, for jittering the hue and saturation of palette colours.
inline void to_hsv(Rgb c, float& h, float& s, float& v) {
  const float mx = std::max({c.r, c.g, c.b}), mn = std::min({c.r, c.g, c.b}), d = mx - mn;
  v = mx;
  s = mx > 0 ? d / mx : 0;
  if (d <= 0) {
    h = 0;
  } else if (mx == c.r) {
    h = std::fmod((c.g - c.b) / d + 6.0f, 6.0f) / 6.0f;
  } else if (mx == c.g) {
    h = ((c.b - c.r) / d + 2.0f) / 6.0f;
  } else {
    h = ((c.r - c.g) / d + 4.0f) / 6.0f;
  }
}

inline Rgb from_hsv(float h, float s, float v) {
  h = (h - std::floor(h)) * 6.0f;
  s = std::clamp(s, 0.0f, 1.0f);
  v = std::clamp(v, 0.0f, 1.0f);
  const int i = std::min(5, static_cast<int>(h));
  const float f = h - static_cast<float>(i), p = v * (1 - s), q = v * (1 - s * f), t = v * (1 - s * (1 - f));
  switch (i) {
    case 0:
      return {v, t, p};
    case 1:
      return {q, v, p};
    case 2:
      return {p, v, t};
    case 3:
      return {p, q, v};
    case 4:
      return {t, p, v};
    default:
      return {v, p, q};
  }
}

// IEC 61966-2-1 sRGB transfer functions.
inline float srgb_to_linear(float c) { return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f); }
inline float linear_to_srgb(float c) {
  return c <= 0.0031308f ? c * 12.92f : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}

}  // namespace texstream::gen
