#pragma once
// What every painter shares: a canvas of sRGB colours, per-texel grain and a precomputed low-frequency noise
// field. Noise is hashed from (texture key, lattice point): deterministic and independent of the thread.
#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

#include "colour.hpp"
#include "rng.hpp"

namespace texstream::gen {

// Mip 0 being painted: width x height RGBA8 texels, row 0 at the top, R in the low byte. `texels` holds rows
// [first_row, row_end()) of it: the whole image, or a band of it (the ground painter paints the city's ground in
// pages band by band, city_ground.hpp); painting outside the band is clipped by fill_rect and must not be set.
struct Canvas {
  uint32_t width;
  uint32_t height;
  std::span<uint32_t> texels;
  uint32_t first_row = 0;

  uint32_t row_end() const { return first_row + static_cast<uint32_t>(texels.size() / width); }
  void set(uint32_t x, uint32_t y, Rgb c) { texels[size_t{y - first_row} * width + x] = pack_rgba8(c); }
};

// Per-texel grain in [-1, 1): one hash per texel.
inline float grain(uint64_t key, uint32_t x, uint32_t y) {
  return unit_float(mix64(key ^ (uint64_t{y} << 32 | x))) * 2.0f - 1.0f;
}

// Smooth value noise in [0, 1], sampled per texel by bilinear interpolation of a lattice of random values
// laid every `cell_px` texels. The lattice is computed once per texture, so a sample costs a few flops
// (painting a million textures must not hash four lattice corners per texel and octave).
class NoiseField {
 public:
  NoiseField(uint64_t key, uint32_t width, uint32_t height, float cell_px) : cell_px_(cell_px < 1 ? 1 : cell_px) {
    gw_ = static_cast<uint32_t>(static_cast<float>(width) / cell_px_) + 2;
    gh_ = static_cast<uint32_t>(static_cast<float>(height) / cell_px_) + 2;
    values_.resize(size_t{gw_} * gh_);
    for (uint32_t j = 0; j < gh_; ++j)
      for (uint32_t i = 0; i < gw_; ++i) values_[size_t{j} * gw_ + i] = unit_float(hash3(key, i, j));
  }

  float at(uint32_t x, uint32_t y) const {
    const float fx = (static_cast<float>(x) + 0.5f) / cell_px_, fy = (static_cast<float>(y) + 0.5f) / cell_px_;
    const uint32_t ix = static_cast<uint32_t>(fx), iy = static_cast<uint32_t>(fy);
    float tx = fx - static_cast<float>(ix), ty = fy - static_cast<float>(iy);
    tx = tx * tx * (3 - 2 * tx);  // smoothstep: no visible lattice creases
    ty = ty * ty * (3 - 2 * ty);
    const float* r0 = &values_[size_t{iy} * gw_ + ix];
    const float* r1 = r0 + gw_;
    const float a = r0[0] + (r0[1] - r0[0]) * tx;
    const float b = r1[0] + (r1[1] - r1[0]) * tx;
    return a + (b - a) * ty;
  }

 private:
  float cell_px_;
  uint32_t gw_ = 0, gh_ = 0;
  std::vector<float> values_;
};

// Fills an axis-aligned rectangle [x0, x1) x [y0, y1) of texels (clipped to the canvas) with `shade(x, y)`.
template <class F>
void fill_rect(Canvas& c, int x0, int y0, int x1, int y1, F&& shade) {
  const int cx0 = std::max(x0, 0), cy0 = std::max(y0, static_cast<int>(c.first_row));
  const int cx1 = std::min(x1, static_cast<int>(c.width)), cy1 = std::min(y1, static_cast<int>(c.row_end()));
  for (int y = cy0; y < cy1; ++y)
    for (int x = cx0; x < cx1; ++x) c.set(static_cast<uint32_t>(x), static_cast<uint32_t>(y), shade(x, y));
}

// Reads a canvas texel back as a colour (for painting over what is there, e.g. shadows).
inline Rgb get_rgb(const Canvas& c, uint32_t x, uint32_t y) {
  const uint32_t v = c.texels[size_t{y - c.first_row} * c.width + x];
  return rgb8(static_cast<int>(v & 0xff), static_cast<int>((v >> 8) & 0xff), static_cast<int>((v >> 16) & 0xff));
}

// Width of a painted line in metres: at least `min_px` texels, so thin details (frames, seams) survive at
// coarse texel densities instead of falling between texel centres.
inline float line_m(float metres, float texel_m, float min_px) {
  return metres > texel_m * min_px ? metres : texel_m * min_px;
}

}  // namespace texstream::gen
