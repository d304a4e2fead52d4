#pragma once
// Internal to the painter: one function per surface kind, all given the same context.
#include "building_style.hpp"
#include "city_layout.hpp"
#include "paint_common.hpp"

namespace texstream::gen {

struct PaintContext {
  const Surface& surface;
  const BuildingStyle& style;
  uint64_t key;   // hash of (seed, texture id): seeds all per-texel noise
  Rng& rng;       // per-texture random choices (window lights, vents, trees)
  float texel_u;  // metres per texel along u (image x)
  float texel_v;  // metres per texel along v (image y)
};

void paint_facade(const PaintContext& ctx, Canvas& canvas);
void paint_utility_wall(const PaintContext& ctx, Canvas& canvas);
void paint_roof(const PaintContext& ctx, Canvas& canvas);
void paint_utility_roof(const PaintContext& ctx, Canvas& canvas);
void paint_ground(const PaintContext& ctx, Canvas& canvas);
void paint_panel(const PaintContext& ctx, Canvas& canvas);

}  // namespace texstream::gen
