#pragma once
// Paints mip 0 of one texture: facades with window grids, floor bands, doors and weathering; roofs with
// gravel, tiles, greenery or solar panels; grounds with streets, sidewalks, courtyards and trees. Never a
// flat colour: the image-error measurements need detail at every mip. A pure function of (seed, texture id,
// surface): byte-identical on any thread.
#include <cstdint>
#include <span>

#include "city_layout.hpp"
#include "rng.hpp"

namespace texstream::gen {

// `texels` holds width_px * height_px RGBA8 texels (R in the low byte), row 0 at the top of the image.
void paint_texture(uint64_t seed, uint32_t texture_id, const Surface& surface, std::span<uint32_t> texels);

// Rows [first_row, first_row + texels.size() / width_px) of a kGround surface's image, texel for texel what
// paint_texture paints there when `stream` is Stream::kTexture and `id` the texture id (the random choices and
// noise are those of the whole image; only the band is written). The city's ground in pages paints its image
// band by band this way (city_ground.hpp).
void paint_ground_rows(uint64_t seed, Stream stream, uint64_t id, const Surface& ground, uint32_t first_row,
                       std::span<uint32_t> texels);

}  // namespace texstream::gen
