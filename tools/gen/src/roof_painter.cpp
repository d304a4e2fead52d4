// Roofs: gravel with parapet, vents and optional solar arrays; clay tiles in courses with a ridge; green
// (sedum) roofs; standing-seam metal. Image row 0 is the roof's north edge.
#include <cmath>

#include "painters.hpp"

namespace texstream::gen {

namespace {

constexpr Rgb kSolarCell{0.12f, 0.16f, 0.28f};
constexpr Rgb kSolarFrame{0.72f, 0.74f, 0.76f};

// Paints square vents / skylights / hatches: small boxes with a light rim and a dark centre.
void paint_vents(const PaintContext& ctx, Canvas& cv, int count) {
  for (int k = 0; k < count; ++k) {
    const float size_m = ctx.rng.uniform(0.5f, 1.4f);
    const int sw = std::max(2, static_cast<int>(size_m / ctx.texel_u));
    const int sh = std::max(2, static_cast<int>(size_m / ctx.texel_v));
    const int x0 = ctx.rng.range(0, std::max(0, static_cast<int>(cv.width) - sw));
    const int y0 = ctx.rng.range(0, std::max(0, static_cast<int>(cv.height) - sh));
    const Rgb rim = rgb8(170, 170, 166), centre = rgb8(70, 72, 74);
    fill_rect(cv, x0, y0, x0 + sw, y0 + sh, [&](int x, int y) {
      const bool edge = x == x0 || y == y0 || x == x0 + sw - 1 || y == y0 + sh - 1;
      const float g = 0.05f * grain(ctx.key ^ 0x3, static_cast<uint32_t>(x), static_cast<uint32_t>(y));
      return (edge ? rim : centre) * (1.0f + g);
    });
    // Shadow to the north-east (sun from the south-west).
    fill_rect(cv, x0 + sw, y0 - 1, x0 + sw + std::max(1, sw / 3), y0 + sh - 1,
              [&](int x, int y) { return get_rgb(cv, static_cast<uint32_t>(x), static_cast<uint32_t>(y)) * 0.7f; });
  }
}

void paint_solar(const PaintContext& ctx, Canvas& cv) {
  // Rows of 1.0 x 1.7 m modules with a 0.6 m aisle, over a rectangle covering part of the roof.
  const float mw = 1.0f, mh = 1.7f, aisle = 0.6f;
  const float x0m = ctx.rng.uniform(0.8f, 2.0f), y0m = ctx.rng.uniform(0.8f, 2.0f);
  const float x1m = ctx.surface.width_m * ctx.rng.uniform(0.55f, 0.92f);
  const float y1m = ctx.surface.height_m * ctx.rng.uniform(0.55f, 0.92f);
  const float frame_u = line_m(0.05f, ctx.texel_u, 0.5f), frame_v = line_m(0.05f, ctx.texel_v, 0.5f);
  fill_rect(cv, static_cast<int>(x0m / ctx.texel_u), static_cast<int>(y0m / ctx.texel_v),
            static_cast<int>(x1m / ctx.texel_u), static_cast<int>(y1m / ctx.texel_v), [&](int x, int y) {
              const float u = (static_cast<float>(x) + 0.5f) * ctx.texel_u - x0m;
              const float v = (static_cast<float>(y) + 0.5f) * ctx.texel_v - y0m;
              const float fv = std::fmod(v, mh + aisle);
              const Rgb under = get_rgb(cv, static_cast<uint32_t>(x), static_cast<uint32_t>(y));
              if (fv > mh) return under * (fv < mh + 0.3f ? 0.6f : 1.0f);  // aisle, shadowed behind the row
              const float fu = std::fmod(u, mw);
              if (fu < frame_u || fv < frame_v || fv > mh - frame_v) return kSolarFrame;
              const float sheen = 0.15f * (1.0f - fv / mh);
              return lerp(kSolarCell, rgb8(120, 140, 180), sheen) *
                     (1.0f + 0.04f * grain(ctx.key ^ 0x5, static_cast<uint32_t>(x), static_cast<uint32_t>(y)));
            });
}

}  // namespace

void paint_roof(const PaintContext& ctx, Canvas& cv) {
  const BuildingStyle& st = ctx.style;
  const float tu = ctx.texel_u, tv = ctx.texel_v;
  const float w_m = ctx.surface.width_m, h_m = ctx.surface.height_m;
  const NoiseField stains(ctx.key ^ 0x11, cv.width, cv.height, 4.0f / tu);
  const NoiseField patches(ctx.key ^ 0x12, cv.width, cv.height, 1.0f / tu);
  const float parapet = line_m(0.35f, std::max(tu, tv), 1.0f);
  const Rgb rim = st.wall * 0.95f;
  // Clay tile courses: at least 2 texels each, so they read as courses rather than aliasing.
  const float course_m = line_m(0.33f, tv, 2.0f), tile_m = line_m(0.25f, tu, 1.0f);
  const float seam_m = line_m(0.5f, tu, 2.0f);

  for (uint32_t y = 0; y < cv.height; ++y) {
    const float v = (static_cast<float>(y) + 0.5f) * tv;
    for (uint32_t x = 0; x < cv.width; ++x) {
      const float u = (static_cast<float>(x) + 0.5f) * tu;
      const float edge = std::min(std::min(u, w_m - u), std::min(v, h_m - v));
      const float g = grain(ctx.key, x, y);
      Rgb col;
      switch (st.roof) {
        case RoofMaterial::kGravel:
          col = st.roof_colour * (0.85f + 0.22f * stains.at(x, y) + 0.12f * g);
          if (edge < parapet)
            col = rim * (0.95f + 0.05f * g);
          else if (edge < parapet + tu * 1.5f)
            col = col * 0.75f;  // the parapet's shadow
          break;
        case RoofMaterial::kTiles: {
          const float course = v / course_m;
          const int64_t ci = static_cast<int64_t>(course);
          const float f = course - static_cast<float>(ci);
          const int64_t ti = static_cast<int64_t>(u / tile_m + ((ci & 1) ? 0.5f : 0.0f));
          const float tone =
              0.85f + 0.25f * unit_float(hash3(ctx.key, static_cast<uint64_t>(ci), static_cast<uint64_t>(ti)));
          col = st.roof_colour * (tone * (0.75f + 0.3f * f));  // each course darker under the one above
          if (std::fabs(v - h_m / 2) < line_m(0.15f, tv, 1.0f)) col = st.roof_colour * 0.6f;  // ridge
          if (patches.at(x, y) > 0.78f) col = lerp(col, rgb8(90, 100, 60), 0.5f);             // moss
          col = col * (1.0f + 0.05f * g);
          break;
        }
        case RoofMaterial::kGreen: {
          const float n = patches.at(x, y), m = stains.at(x, y);
          col = lerp(st.roof_colour, rgb8(150, 140, 70), 0.5f * n * m) * (0.8f + 0.2f * n + 0.1f * g);
          if (edge < parapet * 1.5f) col = rgb8(150, 146, 140) * (0.9f + 0.1f * g);  // gravel strip
          break;
        }
        case RoofMaterial::kMetal: {
          const float fs = std::fmod(u, seam_m) / seam_m;
          col =
              st.roof_colour * (fs < 0.12f ? 1.25f : 0.95f + 0.1f * fs) * (0.92f + 0.12f * stains.at(x, y) + 0.03f * g);
          break;
        }
      }
      cv.set(x, y, col);
    }
  }
  if (st.roof == RoofMaterial::kGravel || st.roof == RoofMaterial::kGreen) {
    if (st.solar && w_m > 6 && h_m > 6) paint_solar(ctx, cv);
    paint_vents(ctx, cv, ctx.rng.range(0, 2 + static_cast<int>(w_m * h_m / 150.0f)));
  }
}

void paint_utility_roof(const PaintContext& ctx, Canvas& cv) {
  // Concrete or sheet-metal lid of a stairwell head or chimney: mottled, with a rim and (if large) a vent.
  const NoiseField stains(ctx.key ^ 0x21, cv.width, cv.height, 1.5f / ctx.texel_u);
  const Rgb base = lerp(ctx.style.wall, rgb8(120, 120, 118), 0.6f);
  for (uint32_t y = 0; y < cv.height; ++y)
    for (uint32_t x = 0; x < cv.width; ++x) {
      const bool rim = x == 0 || y == 0 || x + 1 == cv.width || y + 1 == cv.height;
      cv.set(x, y, base * ((rim ? 1.15f : 0.85f) + 0.2f * stains.at(x, y) + 0.08f * grain(ctx.key, x, y)));
    }
  if (cv.width >= 8 && cv.height >= 8) paint_vents(ctx, cv, 1);
}

}  // namespace texstream::gen
