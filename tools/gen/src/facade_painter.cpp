// Facades: a material (plaster, brick, concrete panels, curtain wall), storeys with window grids, frames and
// glass with sky reflection, doors and shop windows on the ground floor, cornices, weathering and grain.
// Column facts (which window column, where in it) and row facts (which storey, where in it) are computed once
// per column and row; the per-texel work is a few comparisons and multiplies.
#include <cmath>
#include <vector>

#include "painters.hpp"

namespace texstream::gen {

namespace {

constexpr Rgb kSky{0.67f, 0.75f, 0.84f};
constexpr Rgb kLitWarm{0.86f, 0.76f, 0.55f};

struct Column {
  float u;         // metres from the wall's left edge (texel centre)
  float cu;        // metres from the centre of its window column
  int window_col;  // index of the window column
  bool in_window;  // inside a regular window's horizontal span
  bool in_shop;    // inside a shop window's horizontal span
  bool in_door;    // inside the door's horizontal span (door column only)
  bool frame;      // on a window frame's vertical bar or mullion
  float streak;    // weathering streak strength 0..1
  bool mullion;    // curtain wall: on a vertical mullion
};

struct Row {
  float z;         // metres above the street (texel centre)
  int storey;      // 0 = ground floor
  float fz;        // metres above the storey's floor
  bool in_window;  // inside a regular window's vertical span
  float win_t;     // 0 at the window's bottom, 1 at its top
  bool in_shop;
  bool in_door;
  bool frame;  // on a window frame's horizontal bar or transom
  bool cornice;
  bool sill_shadow;
  bool parapet;
  bool spandrel;  // curtain wall: opaque band at the floor slab
  bool seam;      // concrete panels: horizontal seam
};

// A triangle wave in [0, 1] with period 1: a cheap stand-in for a sine in reflections.
float tri(float x) {
  const float f = x - std::floor(x);
  return f < 0.5f ? 2 * f : 2 - 2 * f;
}

}  // namespace

void paint_facade(const PaintContext& ctx, Canvas& cv) {
  const Surface& s = ctx.surface;
  const BuildingStyle& st = ctx.style;
  Rng& rng = ctx.rng;
  const float tu = ctx.texel_u, tv = ctx.texel_v;
  const float wall_w = s.width_m, top = s.base_m + s.height_m;
  const bool at_street = s.base_m <= 0.0f;

  // Window columns evenly spread over the wall; narrow walls still get one column.
  const int ncols = std::max(1, static_cast<int>(wall_w / st.window_pitch_m));
  const float pitch = wall_w / static_cast<float>(ncols);
  const float win_half = std::min(st.window_w_m, pitch * 0.8f) / 2;
  const float shop_half = pitch * 0.4f;
  const int door_col = at_street && wall_w > 3.0f ? rng.range(0, ncols - 1) : -1;
  const float door_half = std::min(0.7f, pitch * 0.4f);
  const float frame_u = line_m(0.09f, tu, 0.7f), frame_v = line_m(0.09f, tv, 0.7f);
  const int nmull = std::max(1, static_cast<int>(std::lround(wall_w / st.panel_w_m)));
  const float mull_pitch = wall_w / static_cast<float>(nmull);
  const float phase = rng.uniform(0.0f, 10.0f), refl_slope = rng.uniform(0.3f, 1.2f);

  std::vector<Column> cols(cv.width);
  for (uint32_t x = 0; x < cv.width; ++x) {
    Column& c = cols[x];
    c.u = (static_cast<float>(x) + 0.5f) * tu;
    c.window_col = std::min(ncols - 1, static_cast<int>(c.u / pitch));
    c.cu = c.u - (static_cast<float>(c.window_col) + 0.5f) * pitch;
    const float a = std::fabs(c.cu);
    c.in_window = a < win_half;
    c.in_shop = a < shop_half && c.window_col != door_col;
    c.in_door = c.window_col == door_col && a < door_half;
    c.frame = (c.in_window && a > win_half - frame_u) || (st.mullion_cross && a < frame_u / 2) ||
              (c.in_shop && a > shop_half - frame_u);
    // Weathering runs down from window corners: a 1-D noise per ~0.7 m strip of wall.
    c.streak = unit_float(hash3(ctx.key, 77, static_cast<uint64_t>(c.u / 0.7f)));
    c.streak = c.streak > 0.6f ? (c.streak - 0.6f) * 2.5f : 0.0f;
    const float m = c.u - std::round(c.u / mull_pitch) * mull_pitch;
    c.mullion = std::fabs(m) < line_m(0.06f, tu, 0.6f);
  }

  const float gf = st.ground_floor_m, fh = st.floor_m;
  const float shop_h = gf * 0.72f, door_h = std::min(2.5f, gf * 0.8f);
  std::vector<Row> rows(cv.height);
  for (uint32_t y = 0; y < cv.height; ++y) {
    Row& r = rows[y];
    r.z = s.base_m + (static_cast<float>(cv.height - y) - 0.5f) * tv;
    if (r.z < gf) {
      r.storey = 0;
      r.fz = r.z;
    } else {
      r.storey = 1 + static_cast<int>((r.z - gf) / fh);
      r.fz = r.z - gf - static_cast<float>(r.storey - 1) * fh;
    }
    const float storey_h = r.storey == 0 ? gf : fh;
    const float wh = std::min(st.window_h_m, storey_h * 0.7f);
    const float sill = (storey_h - wh) * 0.55f;
    r.in_window = r.fz >= sill && r.fz < sill + wh;
    r.win_t = (r.fz - sill) / wh;
    r.frame = r.in_window && (r.fz < sill + frame_v || r.fz > sill + wh - frame_v ||
                              (st.mullion_cross && std::fabs(r.fz - (sill + wh * 0.62f)) < frame_v / 2));
    r.sill_shadow = r.fz < sill && r.fz > sill - line_m(0.12f, tv, 0.8f);
    const bool shop_storey = r.storey == 0 && at_street && st.shop_front;
    r.in_shop = shop_storey && r.fz > 0.35f && r.fz < 0.35f + shop_h;
    if (shop_storey && (r.fz < 0.35f + frame_v || r.fz > 0.35f + shop_h - frame_v) && r.in_shop) r.frame = true;
    r.in_door = r.storey == 0 && at_street && r.fz < door_h;
    r.cornice = st.cornices && r.storey > 0 && r.fz < line_m(0.22f, tv, 1.0f);
    r.parapet = r.z > top - line_m(0.5f, tv, 1.0f);
    r.spandrel = r.fz < std::max(0.9f, tv);
    const float panel_z = std::fmod(r.fz, fh * 0.5f);
    r.seam = panel_z < line_m(0.04f, tv, 0.6f);
  }

  const NoiseField stains(ctx.key ^ 0x5151, cv.width, cv.height, 6.0f / tu);
  const NoiseField fine(ctx.key ^ 0x7272, cv.width, cv.height, 1.2f / tu);
  const float brick_h = line_m(0.075f, tv, 1.0f), brick_w = brick_h * 3.3f;
  const Rgb dark_trim = st.trim * 0.8f;

  for (uint32_t y = 0; y < cv.height; ++y) {
    const Row& r = rows[y];
    for (uint32_t x = 0; x < cv.width; ++x) {
      const Column& c = cols[x];
      const uint64_t win_id = hash3(ctx.key, static_cast<uint64_t>(c.window_col), static_cast<uint64_t>(r.storey));
      Rgb col;
      // 1. The wall material.
      switch (st.material) {
        case FacadeMaterial::kPlaster:
          col = st.wall * (0.93f + 0.1f * fine.at(x, y));
          break;
        case FacadeMaterial::kBrick: {
          const float course = r.z / brick_h;
          const int64_t ci = static_cast<int64_t>(course);
          const float offset = (ci & 1) ? 0.5f : 0.0f;
          const int64_t bi = static_cast<int64_t>(c.u / brick_w + offset);
          const float tone =
              0.82f + 0.3f * unit_float(hash3(ctx.key, static_cast<uint64_t>(ci), static_cast<uint64_t>(bi)));
          const bool mortar = brick_h > 3 * tv && course - static_cast<float>(ci) < 0.18f;
          col = mortar ? rgb8(180, 172, 160) : st.wall * tone;
          break;
        }
        case FacadeMaterial::kPanel: {
          const float pu = std::fmod(c.u, st.panel_w_m);
          const bool seam = pu < line_m(0.04f, tu, 0.6f) || r.seam;
          const uint64_t pid = hash3(ctx.key ^ 0x99, static_cast<uint64_t>(c.u / st.panel_w_m),
                                     static_cast<uint64_t>(r.z / (fh * 0.5f)));
          col = seam ? st.wall * 0.62f : st.wall * (0.92f + 0.12f * unit_float(pid) + 0.05f * fine.at(x, y));
          break;
        }
        case FacadeMaterial::kGlass: {
          if (r.spandrel || r.parapet) {
            col = st.wall * (0.9f + 0.1f * fine.at(x, y));
          } else if (c.mullion) {
            col = dark_trim;
          } else {
            const float refl = tri((c.u * refl_slope + r.z) * 0.04f + phase);
            const float lit = unit_float(win_id) < st.lit_fraction * 0.5f ? 0.25f : 0.0f;
            col = lerp(st.glass, kSky, 0.15f + 0.45f * refl * refl) + kLitWarm * lit;
          }
          break;
        }
      }
      // 2. Openings: windows, shop windows, doors (not on curtain walls, which are all glass).
      if (st.material != FacadeMaterial::kGlass) {
        const bool door = c.in_door && r.in_door;
        const bool shop = !door && c.in_shop && r.in_shop;
        const bool window =
            !door && !shop && c.in_window && r.in_window && !(r.storey == 0 && at_street && st.shop_front);
        if (door) {
          const bool door_edge = std::fabs(c.cu) > door_half - frame_u || r.fz > door_h - frame_v;
          const bool panel_line = std::fabs(std::fabs(c.cu) - door_half * 0.5f) < frame_u * 0.5f;
          col = door_edge ? st.trim : st.accent * (panel_line ? 0.75f : 1.0f);
        } else if (shop || window) {
          if ((shop && (r.frame || c.frame)) || (window && (r.frame || c.frame))) {
            col = st.trim;
          } else {
            // Glass: darker at the bottom, sky reflected at the top, a diagonal highlight across the facade;
            // some windows lit or curtained.
            const float t = shop ? (r.fz - 0.35f) / shop_h : r.win_t;
            const float refl = tri((c.u * refl_slope + r.z) * 0.05f + phase);
            col = lerp(st.glass * 0.7f, kSky, 0.1f + 0.35f * t + 0.25f * refl * refl * refl);
            if (shop)
              col = lerp(col, kLitWarm, 0.35f * unit_float(win_id));
            else if (unit_float(win_id) < st.lit_fraction)
              col = lerp(col, kLitWarm, 0.6f);
          }
        } else if (r.sill_shadow && c.in_window && r.storey > 0) {
          col = col * 0.72f;
        } else if (r.cornice || r.parapet) {
          col = st.material == FacadeMaterial::kPlaster ? st.trim * (0.9f + 0.1f * fine.at(x, y)) : col * 0.8f;
        }
      }
      // 3. Weathering: large stains, streaks running down the wall, grime near the street, grain.
      float k = 0.9f + 0.2f * stains.at(x, y);
      k -= st.dirt * 0.14f * c.streak;
      if (r.z < 2.0f) k -= st.dirt * 0.18f * (1.0f - r.z / 2.0f);
      k += 0.045f * grain(ctx.key, x, y);
      cv.set(x, y, col * k);
    }
  }
}

}  // namespace texstream::gen
