#include "city_layout.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>
#include <vector>

#include "rng.hpp"

namespace texstream::gen {

namespace {

struct Rect {
  double x0, y0, x1, y1;
  double w() const { return x1 - x0; }
  double h() const { return y1 - y0; }
};

// A power of two near metric_m / texel_m, rounded stochastically in log2 so that the expected extent follows
// the metric size smoothly (plain rounding would snap most walls of a city to the same one or two extents).
uint16_t pick_extent(double metric_m, double texel_m, Rng& rng) {
  const double e = std::log2(std::max(metric_m / texel_m, 1.0)) + rng.real();
  const double clamped = std::clamp(std::floor(e), std::log2(double{kMinExtent}), std::log2(double{kMaxExtent}));
  return static_cast<uint16_t>(1u << static_cast<unsigned>(clamped));
}

class LayoutBuilder {
 public:
  LayoutBuilder(uint64_t seed, uint64_t budget) : seed_(seed), budget_(budget) {
    out_.block_pitch_m = kBlockPitchM;
    out_.street_width_m = kStreetWidthM;
    out_.surfaces.reserve(budget);
    // The city's radius if an average block held ~70 textures (measured over the generator's own output);
    // density falls off over ~0.65 of it so the centre is dense and the rim sparse at any texture count.
    const double city_radius = kBlockPitchM * std::sqrt(static_cast<double>(budget) / (70.0 * 3.14159265));
    falloff_m_ = std::max(0.65 * city_radius, 0.8 * kBlockPitchM);
  }

  bool full() const { return out_.surfaces.size() >= budget_; }

  void add_block(int32_t i, int32_t j) {
    const uint64_t block_index = out_.blocks.size();
    Rng rng(seed_, Stream::kBlock, block_index);
    const double cx = i * kBlockPitchM, cy = j * kBlockPitchM;
    const double r = std::hypot(cx, cy) / falloff_m_;
    const float density =
        static_cast<float>(std::clamp((0.08 + 0.92 * std::exp(-r * r)) * rng.real(0.75, 1.15), 0.04, 1.0));
    const bool park = block_index != 0 && rng.chance(0.05f);
    out_.blocks.push_back(Block{i, j, density});

    const double half = kBlockPitchM / 2;
    Surface ground = quad({cx - half, cy - half, 0}, {kBlockPitchM, 0, 0}, {0, kBlockPitchM, 0}, SurfaceKind::kGround,
                          ~0u, BuildingClass::kPerimeter);
    ground.grid = 4;
    ground.variant = park ? 1 : 0;
    const double ground_texel = rng.real(0.2, 0.35);
    ground.width_px = pick_extent(kBlockPitchM, ground_texel, rng);
    ground.height_px = pick_extent(kBlockPitchM, ground_texel, rng);
    out_.surfaces.push_back(ground);
    if (park || full()) return;

    const double inset = kStreetWidthM / 2 + kSidewalkM;
    const Rect interior{cx - half + inset, cy - half + inset, cx + half - inset, cy + half - inset};
    // Lots: perimeter blocks split into street-front parcels of ~10-20 m, villa suburbs into ~25-35 m.
    const double max_lot = 38.0 - 12.0 * static_cast<double>(density);
    std::vector<Rect> lots;
    split_lots(interior, max_lot, rng, lots);
    for (const Rect& lot : lots) {
      if (full()) return;
      const bool on_street =
          lot.x0 == interior.x0 || lot.y0 == interior.y0 || lot.x1 == interior.x1 || lot.y1 == interior.y1;
      // Berlin perimeter blocks: buildings line the streets around an open courtyard.
      if (density > 0.5f && !on_street && rng.chance(0.7f)) continue;
      if (!rng.chance(0.3f + 0.7f * density)) continue;
      add_building(lot, interior, density, rng);
    }
  }

  CityLayout take() { return std::move(out_); }

 private:
  static Surface quad(std::array<double, 3> corner, std::array<double, 3> u, std::array<double, 3> v, SurfaceKind kind,
                      uint32_t building, BuildingClass cls) {
    Surface s{};
    for (int a = 0; a < 3; ++a) {
      s.corner[a] = corner[a];
      s.edge_u[a] = static_cast<float>(u[a]);
      s.edge_v[a] = static_cast<float>(v[a]);
    }
    s.width_m = static_cast<float>(std::hypot(u[0], u[1], u[2]));
    s.height_m = static_cast<float>(std::hypot(v[0], v[1], v[2]));
    s.base_m = static_cast<float>(corner[2]);
    s.building = building;
    s.kind = kind;
    s.cls = cls;
    s.grid = 1;
    return s;
  }

  void split_lots(const Rect& r, double max_side, Rng& rng, std::vector<Rect>& out) {
    if (std::max(r.w(), r.h()) <= max_side) {
      out.push_back(r);
      return;
    }
    const double f = rng.real(0.35, 0.65);
    if (r.w() >= r.h()) {
      const double x = r.x0 + r.w() * f;
      split_lots({r.x0, r.y0, x, r.y1}, max_side, rng, out);
      split_lots({x, r.y0, r.x1, r.y1}, max_side, rng, out);
    } else {
      const double y = r.y0 + r.h() * f;
      split_lots({r.x0, r.y0, r.x1, y}, max_side, rng, out);
      split_lots({r.x0, y, r.x1, r.y1}, max_side, rng, out);
    }
  }

  // Four walls (counter-clockwise seen from above, each wall's u running left to right seen from outside)
  // and a roof for a box over `f` from z0 to z1.
  void add_box(std::vector<Surface>& out, const Rect& f, double z0, double z1, uint32_t building, BuildingClass cls,
               const BuildingStyle& style, bool utility, uint8_t variant, Rng& rng) const {
    const double h = z1 - z0;
    const std::array<std::array<double, 2>, 4> c = {{{f.x0, f.y0}, {f.x1, f.y0}, {f.x1, f.y1}, {f.x0, f.y1}}};
    for (int k = 0; k < 4; ++k) {
      const auto& a = c[static_cast<size_t>(k)];
      const auto& b = c[static_cast<size_t>((k + 1) % 4)];
      Surface s = quad({a[0], a[1], z0}, {b[0] - a[0], b[1] - a[1], 0}, {0, 0, h},
                       utility ? SurfaceKind::kUtilityWall : SurfaceKind::kFacade, building, cls);
      s.variant = variant;
      // Texels need not be square on the surface (texture atlases are not): each axis gets its own jitter.
      s.width_px = pick_extent(s.width_m, style.texel_m * rng.lognormal_factor(0.25f), rng);
      s.height_px = pick_extent(s.height_m, style.texel_m * rng.lognormal_factor(0.25f), rng);
      out.push_back(s);
    }
    Surface roof = quad({f.x0, f.y0, z1}, {f.w(), 0, 0}, {0, f.h(), 0},
                        utility ? SurfaceKind::kUtilityRoof : SurfaceKind::kRoof, building, cls);
    roof.variant = variant;
    roof.width_px = pick_extent(roof.width_m, style.texel_m * rng.lognormal_factor(0.25f), rng);
    roof.height_px = pick_extent(roof.height_m, style.texel_m * rng.lognormal_factor(0.25f), rng);
    out.push_back(roof);
  }

  void add_building(const Rect& lot, const Rect& interior, float density, Rng& rng) {
    const uint32_t id = out_.building_count++;
    BuildingClass cls = BuildingClass::kPerimeter;
    if (density > 0.7f && rng.chance(0.06f + 0.4f * (density - 0.7f))) {
      cls = BuildingClass::kTower;
    } else if (density < 0.2f || (density < 0.4f && rng.chance((0.4f - density) * 5.0f))) {
      cls = BuildingClass::kHouse;
    }
    const BuildingStyle style = make_building_style(seed_, id, cls);

    // Footprint: perimeter buildings stand on the street line and nearly touch their neighbours; houses
    // sit in gardens.
    Rect f = lot;
    const auto margin = [&](double edge, double bound) {
      if (cls == BuildingClass::kHouse) return rng.real(2.5, 6.0);
      return edge == bound ? 0.0 : rng.real(0.0, 1.2);
    };
    f.x0 += margin(lot.x0, interior.x0);
    f.y0 += margin(lot.y0, interior.y0);
    f.x1 -= margin(lot.x1, interior.x1);
    f.y1 -= margin(lot.y1, interior.y1);
    if (f.w() < 5.0 || f.h() < 5.0) return;

    int floors = 0;
    switch (cls) {
      case BuildingClass::kHouse:
        floors = rng.range(1, 2);
        break;
      case BuildingClass::kPerimeter:
        floors = std::clamp(static_cast<int>(std::lround(2.0 + 5.0 * static_cast<double>(density))) + rng.range(-1, 1),
                            2, 8);
        break;
      case BuildingClass::kTower:
        floors = rng.range(10, 24);
        break;  // Berlin: few high-rises, ~125 m at most
    }
    const double height = static_cast<double>(style.ground_floor_m) + (floors - 1) * static_cast<double>(style.floor_m);

    std::vector<Surface> main_box, tier, extras;
    add_box(main_box, f, 0.0, height, id, cls, style, false, 0, rng);
    double top = height;
    Rect top_rect = f;
    if (cls != BuildingClass::kHouse && floors >= 5 && rng.chance(0.3f)) {
      const double in = rng.real(1.5, 4.0);
      const Rect t{f.x0 + in, f.y0 + in, f.x1 - in, f.y1 - in};
      if (t.w() >= 4.0 && t.h() >= 4.0) {
        const int tier_floors = cls == BuildingClass::kTower ? rng.range(2, 4) : rng.range(1, 2);
        top = height + tier_floors * static_cast<double>(style.floor_m);
        add_box(tier, t, height, top, id, cls, style, false, 1, rng);
        top_rect = t;
      }
    }
    if (cls == BuildingClass::kHouse) {
      if (rng.chance(0.35f)) {  // a chimney: the scene's smallest textures (2^2)
        const double s = rng.real(0.5, 0.9);
        const double x = rng.real(f.x0 + 1, f.x1 - 1 - s);
        const double y = rng.real(f.y0 + 1, f.y1 - 1 - s);
        add_box(extras, {x, y, x + s, y + s}, top, top + rng.real(0.8, 1.6), id, cls, style, true, 0, rng);
      }
    } else {
      // Stairwell heads, lift machine rooms, air conditioning: 2^3..2^5 textures.
      const int n = rng.chance(0.75f) ? 0 : rng.range(1, density > 0.6f ? 2 : 1);
      for (int k = 0; k < n; ++k) {
        const double w = rng.real(1.5, 4.0), d = rng.real(1.5, 4.0);
        if (top_rect.w() < w + 2 || top_rect.h() < d + 2) continue;
        const double x = rng.real(top_rect.x0 + 1, top_rect.x1 - 1 - w);
        const double y = rng.real(top_rect.y0 + 1, top_rect.y1 - 1 - d);
        add_box(extras, {x, y, x + w, y + d}, top, top + rng.real(1.5, 3.2), id, cls, style, true, 0, rng);
      }
    }

    // Reach N exactly: drop optional parts that do not fit, whole boxes at a time (5 surfaces each).
    const uint64_t left = budget_ - out_.surfaces.size();
    if (main_box.size() > left) {
      add_panels(f, left, id, style, rng);
      return;
    }
    std::vector<Surface> all = std::move(main_box);
    if (all.size() + tier.size() <= left) {
      all.insert(all.end(), tier.begin(), tier.end());
      for (size_t k = 0; k + 5 <= extras.size() && all.size() + 5 <= left; k += 5)
        all.insert(all.end(), extras.begin() + static_cast<long>(k), extras.begin() + static_cast<long>(k + 5));
    }
    out_.surfaces.insert(out_.surfaces.end(), all.begin(), all.end());
  }

  // The last 1..4 textures of the city: free-standing billboard panels along the lot's south edge.
  void add_panels(const Rect& lot, uint64_t count, uint32_t id, const BuildingStyle& style, Rng& rng) {
    double x = lot.x0;
    const double slot = lot.w() / static_cast<double>(count);
    for (uint64_t k = 0; k < count; ++k) {
      const double w = std::min<double>(slot - 0.5, rng.real(3.0, 6.0)), h = rng.real(2.5, 3.5);
      Surface s = quad({x, lot.y0, 0.0}, {w, 0, 0}, {0, 0, h}, SurfaceKind::kPanel, id, BuildingClass::kPerimeter);
      s.width_px = pick_extent(w, style.texel_m, rng);
      s.height_px = pick_extent(h, style.texel_m, rng);
      out_.surfaces.push_back(s);
      x += slot;
    }
  }

  uint64_t seed_;
  uint64_t budget_;
  double falloff_m_;
  CityLayout out_;
};

// Grid cells ordered by distance from the centre (ties by angle), produced in growing annuli so that the
// sequence is unbounded yet strictly ordered.
class CellSpiral {
 public:
  std::pair<int32_t, int32_t> next() {
    while (pos_ == cells_.size()) grow();
    return cells_[pos_++];
  }

 private:
  void grow() {
    const int32_t lo = outer_, hi = outer_ == 0 ? 4 : outer_ * 2;
    std::vector<std::pair<int32_t, int32_t>> ring;
    for (int32_t i = -hi; i <= hi; ++i)
      for (int32_t j = -hi; j <= hi; ++j) {
        const int64_t d2 = int64_t{i} * i + int64_t{j} * j;
        if ((lo == 0 || d2 > int64_t{lo} * lo) && d2 <= int64_t{hi} * hi) ring.emplace_back(i, j);
      }
    std::sort(ring.begin(), ring.end(), [](const auto& a, const auto& b) {
      const int64_t da = int64_t{a.first} * a.first + int64_t{a.second} * a.second;
      const int64_t db = int64_t{b.first} * b.first + int64_t{b.second} * b.second;
      if (da != db) return da < db;
      return std::atan2(a.second, a.first) < std::atan2(b.second, b.first);
    });
    cells_ = std::move(ring);
    pos_ = 0;
    outer_ = hi;
  }

  std::vector<std::pair<int32_t, int32_t>> cells_;
  size_t pos_ = 0;
  int32_t outer_ = 0;
};

}  // namespace

CityLayout generate_layout(uint64_t seed, uint64_t texture_count) {
  LayoutBuilder builder(seed, texture_count);
  CellSpiral cells;
  while (!builder.full()) {
    const auto [i, j] = cells.next();
    builder.add_block(i, j);
  }
  return builder.take();
}

}  // namespace texstream::gen
