#include "pages_view.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace texstream::bench {

using pages::PageGeometry;
using pages::PageId;

namespace {

struct Vec3 {
  double x, y, z;
};
Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
Vec3 operator*(Vec3 a, double k) { return {a.x * k, a.y * k, a.z * k}; }

struct Basis {
  Vec3 forward, right, up;
  double tan_x, tan_y;
};

Basis basis(const GroundView& view, const GroundPose& p) {
  Basis b;
  b.forward = {std::cos(p.pitch) * std::cos(p.yaw), std::cos(p.pitch) * std::sin(p.yaw), std::sin(p.pitch)};
  b.right = {std::sin(p.yaw), -std::cos(p.yaw), 0};
  b.up = {b.right.y * b.forward.z - b.right.z * b.forward.y, b.right.z * b.forward.x - b.right.x * b.forward.z,
          b.right.x * b.forward.y - b.right.y * b.forward.x};
  b.tan_x = std::tan(view.fov_x / 2);
  b.tan_y = b.tan_x * view.height / view.width;
  return b;
}

// Where the ray through pixel position (px, py) (pixel units, centres at +0.5) meets z = 0, in metres.
bool ground_hit(const GroundView& view, const GroundPose& pose, const Basis& b, double px, double py, double& x,
                double& y, double& t) {
  const double nx = (2 * px / view.width - 1) * b.tan_x, ny = (1 - 2 * py / view.height) * b.tan_y;
  const Vec3 d = b.forward + b.right * nx + b.up * ny;
  if (d.z > -1e-9) return false;
  t = -pose.z / d.z;
  x = pose.x + t * d.x;
  y = pose.y + t * d.y;
  return true;
}

// The page of `level` holding (u, v) (virtual-square units), clamped into the level's grid.
PageId page_at(uint32_t level, double u, double v) {
  const double n = static_cast<double>(1u << level);
  const auto clampi = [&](double c) { return static_cast<uint32_t>(std::clamp(std::floor(c * n), 0.0, n - 1)); };
  return {level, clampi(u), clampi(v)};
}

uint32_t blend(uint32_t a, uint32_t b, double t) {
  uint32_t out = 0;
  for (int c = 0; c < 4; ++c) {
    const double x = (a >> (8 * c)) & 0xffu, y = (b >> (8 * c)) & 0xffu;
    out |= static_cast<uint32_t>(std::lround(x + (y - x) * t)) << (8 * c);
  }
  return out;
}

uint32_t bilinear(const std::array<uint32_t, 4>& tap, double fx, double fy) {
  return blend(blend(tap[0], tap[1], fx), blend(tap[2], tap[3], fx), fy);
}

// One level's bilinear sample at (u, v) from `fetch(x, y)` in that level's texels.
template <class Fetch>
uint32_t sample_level(const PageGeometry& g, uint32_t level, double u, double v, Fetch&& fetch) {
  const double extent = static_cast<double>(uint64_t{g.page_texels} << level);
  const double X = u * extent - 0.5, Y = v * extent - 0.5;
  const double x0 = std::floor(X), y0 = std::floor(Y);
  const auto ix = static_cast<int64_t>(x0), iy = static_cast<int64_t>(y0);
  return bilinear({fetch(ix, iy), fetch(ix + 1, iy), fetch(ix, iy + 1), fetch(ix + 1, iy + 1)}, X - x0, Y - y0);
}

template <class LevelSample>
void draw(const std::vector<GroundSample>& samples, const PageGeometry& g, LevelSample&& at_level,
          std::vector<uint32_t>& rgba) {
  rgba.resize(samples.size());
  for (size_t i = 0; i < samples.size(); ++i) {
    const GroundSample& s = samples[i];
    if (!s.hit) {
      rgba[i] = kGroundBackground;
      continue;
    }
    const auto coarse = static_cast<uint32_t>(std::floor(s.level));
    const double t = s.level - coarse;
    uint32_t c = at_level(i, coarse, s.u, s.v, t <= 0 || coarse + 1 >= g.levels);
    if (t > 0 && coarse + 1 < g.levels) c = blend(c, at_level(i, coarse + 1, s.u, s.v, true), t);
    rgba[i] = c;
  }
}

}  // namespace

std::vector<GroundSample> cast_ground(const GroundView& view, const GroundPose& pose, const PageGeometry& g,
                                      uint32_t step) {
  const Basis b = basis(view, pose);
  const double size = view.metres_per_texel * g.virtual_extent();
  const double w_m = view.metres_per_texel * g.width, h_m = view.metres_per_texel * g.height;
  const uint32_t cols = (view.width + step - 1) / step, rows = (view.height + step - 1) / step;
  std::vector<GroundSample> out(size_t{cols} * rows);
  for (uint32_t r = 0; r < rows; ++r)
    for (uint32_t c = 0; c < cols; ++c) {
      const double px = c * step + 0.5, py = r * step + 0.5;
      double x, y, t;
      GroundSample& s = out[size_t{r} * cols + c];
      if (!ground_hit(view, pose, b, px, py, x, y, t) || x < 0 || y < 0 || x >= w_m || y >= h_m) continue;
      s.hit = true;
      s.u = x / size;
      s.v = y / size;
      s.distance = t;
      // Texels of the finest level per pixel: the longer of the footprint's two edges (one pixel right, one down).
      double rho = 0;
      for (const auto& [dx, dy] : {std::pair{1.0, 0.0}, std::pair{0.0, 1.0}}) {
        double x1, y1, t1;
        if (!ground_hit(view, pose, b, px + dx, py + dy, x1, y1, t1)) {
          rho = 1e30;
          break;
        }
        rho = std::max(rho, std::hypot(x1 - x, y1 - y) / view.metres_per_texel);
      }
      s.level = std::clamp(static_cast<double>(g.levels - 1) - std::log2(std::max(rho, 1e-9)), 0.0,
                           static_cast<double>(g.levels - 1));
    }
  return out;
}

std::vector<pages::PageNeedSample> needbuffer(const GroundView& view, const GroundPose& pose, const PageGeometry& g,
                                              uint32_t step) {
  const auto samples = cast_ground(view, pose, g, step);
  const uint32_t cols = (view.width + step - 1) / step;
  std::vector<pages::PageNeedSample> out;
  out.reserve(samples.size() * 2);
  for (size_t i = 0; i < samples.size(); ++i) {
    const GroundSample& s = samples[i];
    if (!s.hit) continue;
    const auto c = static_cast<uint32_t>(i % cols), r = static_cast<uint32_t>(i / cols);
    const float sx = static_cast<float>(2.0 * (c * step + 0.5) / view.width - 1);
    const float sy = static_cast<float>(2.0 * (r * step + 0.5) / view.height - 1);
    const auto lo = static_cast<uint32_t>(std::floor(s.level));
    const auto hi = std::min(static_cast<uint32_t>(std::ceil(s.level)), g.levels - 1);
    for (uint32_t l = lo; l <= hi; ++l)
      out.push_back({page_at(l, s.u, s.v), sx, sy, static_cast<float>(s.distance), static_cast<float>(s.level)});
  }
  return out;
}

void draw_pages(const std::vector<GroundSample>& samples, const PageGeometry& g, const pages::PageTable& table,
                const PageTexels& texels, std::vector<uint32_t>& rgba, std::vector<float>* shown_level) {
  if (shown_level) shown_level->assign(samples.size(), -1.0f);
  const uint32_t side = g.stored_side();
  draw(
      samples, g,
      [&](size_t i, uint32_t level, double u, double v, bool finer) -> uint32_t {
        const auto shown = table.available(page_at(level, u, v));
        if (!shown) return kGroundBackground;
        if (finer && shown_level) (*shown_level)[i] = static_cast<float>(shown->level);
        const uint32_t* t = texels(*shown);
        const int64_t ox = int64_t{shown->x} * g.page_texels - g.border_texels;
        const int64_t oy = int64_t{shown->y} * g.page_texels - g.border_texels;
        return sample_level(g, shown->level, u, v, [&](int64_t x, int64_t y) {
          // Taps past the border (none with a border of 1 or more) clamp inside the page: a seam, measured.
          const int64_t lx = std::clamp<int64_t>(x - ox, 0, side - 1), ly = std::clamp<int64_t>(y - oy, 0, side - 1);
          return t[static_cast<uint64_t>(ly) * side + static_cast<uint64_t>(lx)];
        });
      },
      rgba);
}

void draw_reference(const std::vector<GroundSample>& samples, const PageGeometry& g, const TexelFetch& fetch,
                    std::vector<uint32_t>& rgba) {
  draw(
      samples, g,
      [&](size_t, uint32_t level, double u, double v, bool) {
        return sample_level(g, level, u, v, [&](int64_t x, int64_t y) { return fetch(level, x, y); });
      },
      rgba);
}

}  // namespace texstream::bench
