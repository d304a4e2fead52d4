#include "texture_painter.hpp"

#include "painters.hpp"
#include "texstream/common/contract.hpp"

namespace texstream::gen {

void paint_texture(uint64_t seed, uint32_t texture_id, const Surface& surface, std::span<uint32_t> texels) {
  TS_ASSERT(texels.size() == size_t{surface.width_px} * surface.height_px, "canvas of %zu texels for %ux%u",
            texels.size(), surface.width_px, surface.height_px);
  Rng rng(seed, Stream::kTexture, texture_id);
  const BuildingStyle style = make_building_style(seed, surface.building, surface.cls);
  const PaintContext ctx{surface,
                         style,
                         hash3(seed, static_cast<uint64_t>(Stream::kTexture) << 32, texture_id),
                         rng,
                         surface.width_m / static_cast<float>(surface.width_px),
                         surface.height_m / static_cast<float>(surface.height_px)};
  Canvas canvas{surface.width_px, surface.height_px, texels};
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

}  // namespace texstream::gen
