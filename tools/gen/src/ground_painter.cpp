// Block grounds: each block's ground reaches to the centre lines of its streets, so neighbouring grounds
// join into a street network: asphalt with dashed centre lines and zebra crossings, curbs, paved sidewalks,
// and inside the block a courtyard (paving, lawns, sand) or a park with paths, all with trees; beyond the city's
// blocks (variant 2, only in the city's ground in pages: city_ground.hpp) the grid goes on around open land.
// Image row 0 is the block's north edge. Only the canvas's band of rows is painted (paint_common.hpp Canvas).
#include <cmath>

#include "painters.hpp"

namespace texstream::gen {

namespace {

constexpr Rgb kAsphalt{0.25f, 0.255f, 0.265f};
constexpr Rgb kMarking{0.88f, 0.88f, 0.84f};
constexpr Rgb kCurb{0.66f, 0.65f, 0.62f};
constexpr Rgb kSidewalk{0.58f, 0.56f, 0.53f};
constexpr Rgb kPaving{0.66f, 0.63f, 0.58f};
constexpr Rgb kGrass{0.33f, 0.45f, 0.22f};
constexpr Rgb kGravelPath{0.72f, 0.67f, 0.55f};
constexpr Rgb kSand{0.80f, 0.72f, 0.55f};
constexpr Rgb kSoil{0.48f, 0.40f, 0.29f};

void paint_trees(const PaintContext& ctx, Canvas& cv, int count, float lo_m, float hi_m) {
  for (int k = 0; k < count; ++k) {
    const float r_m = ctx.rng.uniform(2.0f, 5.0f);
    const float cx_m = ctx.rng.uniform(lo_m + r_m, hi_m - r_m), cy_m = ctx.rng.uniform(lo_m + r_m, hi_m - r_m);
    const Rgb leaf = lerp(rgb8(40, 72, 34), rgb8(90, 110, 50), ctx.rng.uniform());
    const float cx = cx_m / ctx.texel_u, cy = cy_m / ctx.texel_v;
    const float rx = r_m / ctx.texel_u, ry = r_m / ctx.texel_v;
    // Shadow first, cast to the north-east (sun from the south-west), then the crown over it.
    const float sx = cx + rx * 0.5f, sy = cy - ry * 0.5f;
    fill_rect(cv, static_cast<int>(sx - rx), static_cast<int>(sy - ry), static_cast<int>(sx + rx) + 1,
              static_cast<int>(sy + ry) + 1, [&](int x, int y) {
                const float dx = (static_cast<float>(x) + 0.5f - sx) / rx,
                            dy = (static_cast<float>(y) + 0.5f - sy) / ry;
                const Rgb under = get_rgb(cv, static_cast<uint32_t>(x), static_cast<uint32_t>(y));
                return dx * dx + dy * dy < 1 ? under * 0.6f : under;
              });
    fill_rect(cv, static_cast<int>(cx - rx), static_cast<int>(cy - ry), static_cast<int>(cx + rx) + 1,
              static_cast<int>(cy + ry) + 1, [&](int x, int y) {
                const float dx = (static_cast<float>(x) + 0.5f - cx) / rx,
                            dy = (static_cast<float>(y) + 0.5f - cy) / ry;
                const float d2 = dx * dx + dy * dy;
                const Rgb under = get_rgb(cv, static_cast<uint32_t>(x), static_cast<uint32_t>(y));
                if (d2 >= 1) return under;
                // Lit from the south-west: brighter towards -x, +y (image down is south).
                const float light = 0.8f + 0.3f * (-dx + dy) * 0.5f;
                const float g = grain(ctx.key ^ 0x7, static_cast<uint32_t>(x), static_cast<uint32_t>(y));
                return leaf * (light * (0.85f + 0.25f * g * g));
              });
  }
}

}  // namespace

void paint_ground(const PaintContext& ctx, Canvas& cv) {
  const float tu = ctx.texel_u, tv = ctx.texel_v;
  const float size = ctx.surface.width_m;
  const bool park = ctx.surface.variant == 1, open_land = ctx.surface.variant == 2;
  const float street = static_cast<float>(kStreetWidthM) / 2, walk = street + static_cast<float>(kSidewalkM);
  const float line = line_m(0.12f, std::max(tu, tv), 0.6f);
  const float curb = line_m(0.25f, std::max(tu, tv), 1.0f);
  const float slab = line_m(0.6f, std::max(tu, tv), 3.0f);
  const NoiseField stains(ctx.key ^ 0x31, cv.width, cv.height, 5.0f / tu);
  const NoiseField zones(ctx.key ^ 0x32, cv.width, cv.height, 18.0f / tu);
  const NoiseField fine(ctx.key ^ 0x33, cv.width, cv.height, 0.8f / tu);
  const float path_a = ctx.rng.uniform(0.2f, 0.8f) * size, path_b = ctx.rng.uniform(0.2f, 0.8f) * size;

  for (uint32_t y = cv.first_row; y < cv.row_end(); ++y) {
    const float v = size - (static_cast<float>(y) + 0.5f) * tv;  // metres north of the block's south edge
    for (uint32_t x = 0; x < cv.width; ++x) {
      const float u = (static_cast<float>(x) + 0.5f) * tu;
      const float ex = std::min(u, size - u), ey = std::min(v, size - v);
      const float e = std::min(ex, ey);
      // Along-street position measured from the nearer corner, for dashes and crossings.
      const float along = ex < ey ? ey : ex;
      const float g = grain(ctx.key, x, y);
      Rgb col;
      if (e < street) {
        col = kAsphalt * (0.85f + 0.25f * stains.at(x, y) + 0.1f * g);
        const bool in_junction = along < walk;
        const float from_junction = along - walk;
        if (!in_junction && from_junction < 4.0f && std::fmod(e, 1.0f) < 0.5f) {
          col = kMarking * (0.9f + 0.1f * g);  // zebra crossing
        } else if (!in_junction && e < line && std::fmod(from_junction, 9.0f) > 6.0f) {
          col = kMarking * (0.9f + 0.1f * g);  // dashed centre line (3 m on, 6 m off)
        }
      } else if (e < street + curb) {
        col = kCurb * (0.95f + 0.05f * g);
      } else if (e < walk) {
        const bool joint = std::fmod(u, slab) < tu * 0.9f || std::fmod(v, slab) < tv * 0.9f;
        col = kSidewalk * ((joint ? 0.8f : 0.95f + 0.1f * fine.at(x, y)) + 0.05f * g);
      } else if (open_land) {
        // Meadow with patches of bare soil, no paving: the outskirts the grid has not built on yet.
        const float z = zones.at(x, y);
        col = z < 0.7f ? kGrass * (0.85f + 0.3f * fine.at(x, y) + 0.15f * stains.at(x, y) + 0.08f * g)
                       : kSoil * (0.9f + 0.15f * fine.at(x, y) + 0.06f * g);
      } else if (park) {
        const float d1 = std::fabs(u - v - (path_a - size / 2)) * 0.7071f,
                    d2 = std::fabs(u + v - path_b - size / 2) * 0.7071f;
        col = std::min(d1, d2) < 1.5f ? kGravelPath * (0.9f + 0.1f * g)
                                      : kGrass * (0.8f + 0.3f * fine.at(x, y) + 0.15f * stains.at(x, y) + 0.08f * g);
      } else {
        const float z = zones.at(x, y);
        if (z < 0.5f) {
          const bool joint = std::fmod(u, slab) < tu * 0.9f || std::fmod(v, slab) < tv * 0.9f;
          col = kPaving * ((joint ? 0.82f : 0.95f) + 0.1f * stains.at(x, y) + 0.05f * g);
        } else if (z < 0.85f) {
          col = kGrass * (0.8f + 0.3f * fine.at(x, y) + 0.08f * g);
        } else {
          col = kSand * (0.9f + 0.1f * fine.at(x, y) + 0.06f * g);
        }
      }
      cv.set(x, y, col);
    }
  }
  const float interior = size - 2 * walk;
  const int trees = park        ? static_cast<int>(interior * interior / 120.0f)
                    : open_land ? ctx.rng.range(0, 4)
                                : ctx.rng.range(2, 10);
  paint_trees(ctx, cv, trees, walk + 1, size - walk - 1);
}

}  // namespace texstream::gen
