#include "texture_painter.hpp"

#include "painters.hpp"
#include "texstream/common/contract.hpp"

namespace texstream::gen {

namespace {

void paint(uint64_t seed, Stream stream, uint64_t id, const Surface& surface, Canvas& canvas) {
  Rng rng(seed, stream, id);
  const BuildingStyle style = make_building_style(seed, surface.building, surface.cls);
  const PaintContext ctx{surface,
                         style,
                         hash3(seed, static_cast<uint64_t>(stream) << 32, id),
                         rng,
                         surface.width_m / static_cast<float>(surface.width_px),
                         surface.height_m / static_cast<float>(surface.height_px)};
  switch (surface.kind) {
    case SurfaceKind::kFacade:
      paint_facade(ctx, canvas);
      break;
    case SurfaceKind::kRoof:
      paint_roof(ctx, canvas);
      break;
    case SurfaceKind::kGround:
      paint_ground(ctx, canvas);
      break;
    case SurfaceKind::kUtilityWall:
      paint_utility_wall(ctx, canvas);
      break;
    case SurfaceKind::kUtilityRoof:
      paint_utility_roof(ctx, canvas);
      break;
    case SurfaceKind::kPanel:
      paint_panel(ctx, canvas);
      break;
  }
}

}  // namespace

void paint_texture(uint64_t seed, uint32_t texture_id, const Surface& surface, std::span<uint32_t> texels) {
  TS_ASSERT(texels.size() == size_t{surface.width_px} * surface.height_px, "canvas of %zu texels for %ux%u",
            texels.size(), surface.width_px, surface.height_px);
  Canvas canvas{surface.width_px, surface.height_px, texels};
  paint(seed, Stream::kTexture, texture_id, surface, canvas);
}

void paint_ground_rows(uint64_t seed, Stream stream, uint64_t id, const Surface& ground, uint32_t first_row,
                       std::span<uint32_t> texels) {
  TS_ASSERT(ground.kind == SurfaceKind::kGround, "paint_ground_rows: surface kind %d is not a ground",
            static_cast<int>(ground.kind));
  TS_ASSERT(texels.size() % ground.width_px == 0 && first_row + texels.size() / ground.width_px <= ground.height_px,
            "band of %zu texels from row %u for %ux%u", texels.size(), first_row, ground.width_px, ground.height_px);
  Canvas canvas{ground.width_px, ground.height_px, texels, first_row};
  paint(seed, stream, id, ground, canvas);
}

}  // namespace texstream::gen
