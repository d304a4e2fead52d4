#pragma once
// --ground pages (issue 28): the city's ground as one huge texture, an orthophoto-like image of every block's
// ground (half streets, sidewalks, courtyard or park) at its place in the street grid, painted by the ground
// painter at the image's scale and baked into a page file by texstream-tile's engine (docs/design/pages.md); the
// blocks' kGround surfaces are then no meshes of the scene. The image covers the grid cells of the blocks'
// bounding rectangle; a cell without a block holds open land inside the continuing street grid.
#include <cstdint>
#include <filesystem>
#include <functional>

#include "city_layout.hpp"
#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::gen {

// Metres per texel of the finest level when none is asked for: 0.25 m puts ~2 texels across a curb and keeps the
// 0.12 m centre lines at their one-texel minimum (an orthophoto's ground sampling distance is 0.1-0.4 m)...
inline constexpr double kGroundTexelM = 0.25;
// ...coarsened (whole texels per block still) when the image would pass this many texels a side: 1 GiB of RGBA8,
// which the baker holds 1.25 times (the finest level and the next).
inline constexpr uint32_t kGroundAutoMaxSide = 16384;
// What an asked-for texel size may give: a Surface's extent is 16 bits, the page file's square 2^18.
inline constexpr uint32_t kGroundMaxBlockPx = 0xffff;

// Where the image lies: grid cells [i0, i0 + cells_x) x [j0, j0 + cells_y) (Block::i, j), block_px texels a cell
// side, image row 0 at the south edge (the page file's v grows north: scene_format.hpp GroundPages).
struct GroundPlan {
  int32_t i0 = 0, j0 = 0;
  uint32_t cells_x = 0, cells_y = 0;
  uint32_t block_px = 0;
  double metres_per_texel = 0;  // kBlockPitchM / block_px
  double z_m = 0;               // city-local height of the ground: that of the blocks' kGround surfaces

  uint32_t width() const { return cells_x * block_px; }
  uint32_t height() const { return cells_y * block_px; }
  // City-local metres of the image's south-west corner (texel (0, 0)'s outer corner).
  double west_m() const { return (i0 - 0.5) * kBlockPitchM; }
  double south_m() const { return (j0 - 0.5) * kBlockPitchM; }
};

// `texel_m`: the finest level's metres per texel as asked for (--ground-texel-m), rounded to the nearest size that
// puts a whole number of texels across a block pitch (0.25 m: 480); 0: kGroundTexelM, coarsened to keep the image
// within kGroundAutoMaxSide a side. Errors name --ground-texel-m.
Result<GroundPlan> plan_ground(const CityLayout& city, double texel_m);

// A block's kGround surface as the city's ground paints it: the same surface at the image's scale.
Surface ground_at_scale(const Surface& ground, uint32_t block_px);

// Rows [y0, y0 + rows) of the image (row 0 south), plan.width() texels each, sRGB RGBA8 (R in the low byte): what
// the page file's finest level holds. A pure function of (seed, layout, plan, rows), callable from any thread.
// `city` is the whole layout: a kGround surface's index in it seeds its painting, as in the meshes' scene.
void paint_city_ground_rows(const CityLayout& city, const GroundPlan& plan, uint64_t seed, uint32_t y0, uint32_t rows,
                            uint32_t* out);

enum class GroundPhase { kPaint, kBake };
// Called from worker threads (must be thread-safe): image rows painted (kPaint), pages written (kBake).
using GroundProgressFn = std::function<void(GroundPhase phase, uint64_t done, uint64_t total)>;

struct GroundBakeStats {
  uint64_t stored_pages = 0;
  uint64_t file_bytes = 0;
  double seconds = 0;  // painting and baking
};

// Paints the image band by band straight into the baker's finest level (no copy of it is held) and writes it as a
// page file to `out` (128-texel pages with 4-texel borders, clamped; through a temporary file renamed into place).
Result<GroundBakeStats> bake_city_ground(const CityLayout& city, const GroundPlan& plan, uint64_t seed,
                                         TexelFormat format, unsigned threads, const std::filesystem::path& out,
                                         const GroundProgressFn& progress = {});

}  // namespace texstream::gen
