// Small surfaces: walls of rooftop structures and chimneys (louvres, ribs, a door or brick), and the
// free-standing billboard panels.
#include <cmath>

#include "painters.hpp"

namespace texstream::gen {

void paint_utility_wall(const PaintContext& ctx, Canvas& cv) {
  const float tu = ctx.texel_u, tv = ctx.texel_v;
  const Surface& s = ctx.surface;
  const bool chimney = s.width_m < 1.0f;
  const Rgb base =
      chimney ? lerp(ctx.style.wall, rgb8(130, 60, 45), 0.6f) : lerp(ctx.style.wall, rgb8(150, 150, 148), 0.5f);
  const float rib = line_m(0.3f, tv, 2.0f);
  const bool door = !chimney && s.width_m > 1.6f && ctx.rng.chance(0.5f);
  const float door_u0 = s.width_m * 0.5f - 0.45f, door_u1 = door_u0 + 0.9f, door_h = std::min(2.0f, s.height_m - 0.2f);
  const NoiseField stains(ctx.key ^ 0x41, cv.width, cv.height, 1.0f / tu);
  for (uint32_t y = 0; y < cv.height; ++y) {
    const float z = (static_cast<float>(cv.height - y) - 0.5f) * tv;  // above the roof it stands on
    for (uint32_t x = 0; x < cv.width; ++x) {
      const float u = (static_cast<float>(x) + 0.5f) * tu;
      const float g = grain(ctx.key, x, y);
      Rgb col;
      if (door && u > door_u0 && u < door_u1 && z < door_h) {
        col = rgb8(70, 76, 82) * (0.95f + 0.05f * g);
      } else if (chimney) {
        const int64_t course = static_cast<int64_t>(z / std::max(tv, 0.08f));
        col = base * (0.8f + 0.3f * unit_float(hash3(ctx.key, static_cast<uint64_t>(course), x / 2)));
      } else {
        const float f = std::fmod(z, rib) / rib;  // louvre ribs, lit from above
        col = base * (0.8f + 0.25f * f);
      }
      cv.set(x, y, col * (0.88f + 0.2f * stains.at(x, y) + 0.06f * g));
    }
  }
}

void paint_panel(const PaintContext& ctx, Canvas& cv) {
  // A poster: two to four colour fields, blocks of "text", a frame.
  Rgb fields[4];
  const int n = ctx.rng.range(2, 4);
  for (int k = 0; k < n; ++k)
    fields[k] = from_hsv(ctx.rng.uniform(), ctx.rng.uniform(0.4f, 0.9f), ctx.rng.uniform(0.5f, 1.0f));
  const Rgb ink = ctx.rng.chance(0.5f) ? rgb8(20, 20, 24) : rgb8(245, 245, 240);
  for (uint32_t y = 0; y < cv.height; ++y)
    for (uint32_t x = 0; x < cv.width; ++x) {
      const bool frame = x == 0 || y == 0 || x + 1 == cv.width || y + 1 == cv.height;
      const uint32_t band = y * static_cast<uint32_t>(n) / cv.height;
      const bool text = (y / 2) % 3 == 1 && unit_float(hash3(ctx.key, x / 3, y / 6)) < 0.55f && band == 0;
      const Rgb col = frame ? rgb8(60, 62, 60) : text ? ink : fields[band];
      cv.set(x, y, col * (0.92f + 0.08f * grain(ctx.key, x, y)));
    }
}

}  // namespace texstream::gen
