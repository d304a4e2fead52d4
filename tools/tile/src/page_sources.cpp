// The sources a bake reads its finest level from: an image file, or a painted orthophoto-like ground.
#include <algorithm>
#include <cmath>
#include <cstring>

#include "page_baker.hpp"

#define STB_IMAGE_STATIC
#define STB_IMAGE_IMPLEMENTATION
#include <stb_image.h>

namespace texstream::tile {

namespace {

class ImageSource final : public PageSource {
 public:
  ImageSource(uint32_t w, uint32_t h, std::vector<uint32_t> texels) : w_(w), h_(h), texels_(std::move(texels)) {}
  Extent2D extent() const override { return {w_, h_}; }
  Status fill_rows(uint32_t y0, uint32_t rows, uint32_t* out) const override {
    std::memcpy(out, texels_.data() + uint64_t{y0} * w_, uint64_t{rows} * w_ * sizeof(uint32_t));
    return ok_status();
  }

 private:
  uint32_t w_, h_;
  std::vector<uint32_t> texels_;
};

uint64_t mix(uint64_t v) {  // splitmix64's finaliser: a well-spread hash of a lattice point
  v += 0x9e3779b97f4a7c15ull;
  v = (v ^ (v >> 30)) * 0xbf58476d1ce4e5b9ull;
  v = (v ^ (v >> 27)) * 0x94d049bb133111ebull;
  return v ^ (v >> 31);
}

double hash01(uint64_t seed, int64_t a, int64_t b, uint64_t salt = 0) {
  const uint64_t h = mix(seed ^ mix(static_cast<uint64_t>(a) * 0x632be59bd9b4e019ull ^ mix(static_cast<uint64_t>(b)) ^
                                    salt * 0x8cb92ba72f3d8dd7ull));
  return static_cast<double>(h >> 11) * 0x1.0p-53;
}

// Smooth value noise on a lattice of `cell` metres, three octaves.
double fbm(uint64_t seed, double x, double y, double cell) {
  double sum = 0, amp = 0.5, norm = 0;
  for (int o = 0; o < 3; ++o, cell *= 0.5, amp *= 0.5) {
    const double u = x / cell, v = y / cell, fu = std::floor(u), fv = std::floor(v);
    const auto ix = static_cast<int64_t>(fu), iy = static_cast<int64_t>(fv);
    const double su = (u - fu) * (u - fu) * (3 - 2 * (u - fu)), sv = (v - fv) * (v - fv) * (3 - 2 * (v - fv));
    const double a = hash01(seed, ix, iy, o), b = hash01(seed, ix + 1, iy, o), c = hash01(seed, ix, iy + 1, o),
                 d = hash01(seed, ix + 1, iy + 1, o);
    sum += amp * ((1 - sv) * ((1 - su) * a + su * b) + sv * ((1 - su) * c + su * d));
    norm += amp;
  }
  return sum / norm;
}

struct Rgb {
  double r, g, b;
};
Rgb operator*(Rgb c, double k) { return {c.r * k, c.g * k, c.b * k}; }
Rgb lerp(Rgb a, Rgb b, double t) { return {a.r + (b.r - a.r) * t, a.g + (b.g - a.g) * t, a.b + (b.b - a.b) * t}; }

uint32_t pack(Rgb c) {
  auto q = [](double v) { return static_cast<uint32_t>(std::clamp(v, 0.0, 1.0) * 255.0 + 0.5); };
  return q(c.r) | (q(c.g) << 8) | (q(c.b) << 16) | 0xff000000u;
}

// Streets 14 m wide between blocks of a jittered grid; blocks of roofs with courtyards, parks or plazas.
class PaintedGround final : public PageSource {
 public:
  PaintedGround(uint32_t w, uint32_t h, double m, uint64_t seed) : w_(w), h_(h), m_(m), seed_(mix(seed)) {}
  Extent2D extent() const override { return {w_, h_}; }
  Status fill_rows(uint32_t y0, uint32_t rows, uint32_t* out) const override {
    for (uint32_t j = 0; j < rows; ++j)
      for (uint32_t x = 0; x < w_; ++x) out[uint64_t{j} * w_ + x] = texel(x, y0 + j);
    return ok_status();
  }

 private:
  static constexpr double kPitch = 110, kStreet = 14, kWalk = 3;

  uint32_t texel(uint32_t tx, uint32_t ty) const {
    const double X = (tx + 0.5) * m_, Y = (ty + 0.5) * m_;
    const auto bx = static_cast<int64_t>(std::floor(X / kPitch)), by = static_cast<int64_t>(std::floor(Y / kPitch));
    const double lx = X - static_cast<double>(bx) * kPitch, ly = Y - static_cast<double>(by) * kPitch;
    const double grain = 0.92 + 0.16 * hash01(seed_, tx, ty, 7);  // texel-scale grain: detail at every level
    const double edge = std::min(lx, ly);
    if (edge < kStreet) {  // street: asphalt, a dashed centre line along each direction
      const bool along_x = ly < kStreet && (lx >= kStreet || ly < lx);
      const double across = along_x ? ly : lx, along = along_x ? lx : ly;
      Rgb c{0.25, 0.255, 0.265};
      if (std::fabs(across - kStreet / 2) < 0.15 && std::fmod(along, 6.0) < 3.0) c = {0.88, 0.88, 0.84};
      return pack(c * (grain * (0.85 + 0.3 * fbm(seed_, X, Y, 24))));
    }
    if (edge < kStreet + kWalk) return pack(Rgb{0.58, 0.56, 0.53} * grain);  // sidewalk
    const double kind = hash01(seed_, bx, by, 1);
    const double ix = lx - kStreet - kWalk, iy = ly - kStreet - kWalk, inner = kPitch - kStreet - kWalk;
    if (kind < 0.2) return pack(park(X, Y) * grain);
    if (kind < 0.28) return pack(Rgb{0.66, 0.63, 0.58} * (grain * (0.95 + 0.1 * fbm(seed_, X, Y, 6))));  // plaza
    // Buildings along the block's edge, a courtyard inside; lots of 12-24 m along the edge, each its own roof.
    const double depth = 14 + 6 * hash01(seed_, bx, by, 2);
    if (ix > depth && iy > depth && ix < inner - depth && iy < inner - depth)
      return pack((hash01(seed_, bx, by, 3) < 0.5 ? park(X, Y) : Rgb{0.62, 0.6, 0.55} * grain) * grain);
    const bool horizontal = iy <= depth || iy >= inner - depth;
    const double along = horizontal ? ix : iy;
    const double lot_m = 12 + 12 * hash01(seed_, bx, by, 4);
    const auto lot = static_cast<int64_t>(along / lot_m);
    const double roof = hash01(seed_, bx * 131 + lot, by, horizontal ? 5 : 6);
    Rgb c = roof < 0.45 ? Rgb{0.55, 0.24, 0.18} : roof < 0.75 ? Rgb{0.42, 0.42, 0.44} : Rgb{0.30, 0.30, 0.32};
    c = c * (0.8 + 0.4 * hash01(seed_, lot, bx + by, 8));
    const double across = horizontal ? std::min(iy, std::fabs(inner - iy)) : std::min(ix, std::fabs(inner - ix));
    if (std::fabs(across - depth / 2) < 0.3) c = c * 0.7;  // ridge line
    if (std::fmod(along, lot_m) < 0.4) c = c * 0.6;        // firewall between lots
    if (across > depth / 2 && roof < 0.45) c = c * 0.85;   // the shaded side of a pitched roof
    return pack(c * (grain * (0.95 + 0.1 * hash01(seed_, static_cast<int64_t>(X * 2), static_cast<int64_t>(Y * 2),
                                                  9))));  // tiles
  }

  Rgb park(double X, double Y) const {
    Rgb c = lerp(Rgb{0.28, 0.40, 0.18}, Rgb{0.40, 0.50, 0.24}, fbm(seed_, X, Y, 16));
    // Trees on a jittered 9 m lattice: a crown, its shadow to the north-east.
    const auto cx = static_cast<int64_t>(std::floor(X / 9)), cy = static_cast<int64_t>(std::floor(Y / 9));
    for (int64_t dy = -1; dy <= 1; ++dy) {
      for (int64_t dx = -1; dx <= 1; ++dx) {
        const int64_t gx = cx + dx, gy = cy + dy;
        if (hash01(seed_, gx, gy, 10) < 0.4) continue;
        const double tx = (static_cast<double>(gx) + hash01(seed_, gx, gy, 11)) * 9;
        const double ty = (static_cast<double>(gy) + hash01(seed_, gx, gy, 12)) * 9;
        const double r = 2 + 2.5 * hash01(seed_, gx, gy, 13);
        const double d2 = (X - tx) * (X - tx) + (Y - ty) * (Y - ty);
        if (d2 < r * r) return lerp(Rgb{0.16, 0.28, 0.13}, Rgb{0.33, 0.43, 0.2}, 1 - d2 / (r * r));
        const double sx = tx + r * 0.5, sy = ty - r * 0.5;
        if ((X - sx) * (X - sx) + (Y - sy) * (Y - sy) < r * r) c = c * 0.6;
      }
    }
    return c;
  }

  uint32_t w_, h_;
  double m_;
  uint64_t seed_;
};

}  // namespace

Result<std::unique_ptr<PageSource>> open_image_source(const std::filesystem::path& path) {
  int w = 0, h = 0, n = 0;
  stbi_uc* p = stbi_load(path.c_str(), &w, &h, &n, 4);
  if (!p)
    return make_error(std::filesystem::exists(path) ? ErrorCode::kUnsupported : ErrorCode::kNotFound,
                      path.string() + ": cannot read the image: " + stbi_failure_reason());
  std::vector<uint32_t> texels(uint64_t(w) * uint64_t(h));
  std::memcpy(texels.data(), p, texels.size() * sizeof(uint32_t));
  stbi_image_free(p);
  return std::unique_ptr<PageSource>(
      new ImageSource(static_cast<uint32_t>(w), static_cast<uint32_t>(h), std::move(texels)));
}

std::unique_ptr<PageSource> make_painted_ground(uint32_t width, uint32_t height, double metres_per_texel,
                                                uint64_t seed) {
  return std::make_unique<PaintedGround>(width, height, metres_per_texel, seed);
}

}  // namespace texstream::tile
