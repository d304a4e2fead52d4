#pragma once
// Paints mip 0 of one texture: facades with window grids, floor bands, doors and weathering; roofs with
// gravel, tiles, greenery or solar panels; grounds with streets, sidewalks, courtyards and trees. Never a
// flat colour: the image-error measurements need detail at every mip. A pure function of (seed, texture id,
// surface): byte-identical on any thread.
#include <cstdint>
#include <span>

#include "city_layout.hpp"

namespace texstream::gen {

// `texels` holds width_px * height_px RGBA8 texels (R in the low byte), row 0 at the top of the image.
void paint_texture(uint64_t seed, uint32_t texture_id, const Surface& surface, std::span<uint32_t> texels);

}  // namespace texstream::gen
