#include "city_ground.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "page_baker.hpp"
#include "texstream/common/contract.hpp"
#include "texstream/common/page_file.hpp"
#include "texture_painter.hpp"

namespace texstream::gen {

namespace {

// The grid cell of a block's ground (its surface spans the cell: city_layout.cpp add_block).
std::pair<int32_t, int32_t> cell_of(const Surface& ground) {
  return {static_cast<int32_t>(std::lround(ground.corner[0] / kBlockPitchM + 0.5)),
          static_cast<int32_t>(std::lround(ground.corner[1] / kBlockPitchM + 0.5))};
}

// Which layout surface paints each cell of the plan; kNoBlock: open land.
class CityGroundPainter {
 public:
  static constexpr uint64_t kNoBlock = std::numeric_limits<uint64_t>::max();

  CityGroundPainter(const CityLayout& city, const GroundPlan& plan, uint64_t seed)
      : city_(city), plan_(plan), seed_(seed), cells_(uint64_t{plan.cells_x} * plan.cells_y, kNoBlock) {
    for (uint64_t k = 0; k < city.surfaces.size(); ++k) {
      const Surface& s = city.surfaces[k];
      if (s.kind != SurfaceKind::kGround) continue;
      const auto [i, j] = cell_of(s);
      TS_ASSERT(i >= plan.i0 && j >= plan.j0 && i - plan.i0 < static_cast<int64_t>(plan.cells_x) &&
                    j - plan.j0 < static_cast<int64_t>(plan.cells_y),
                "ground of surface %llu in cell (%d, %d), outside the plan", static_cast<unsigned long long>(k), i, j);
      cells_[static_cast<uint64_t>(j - plan.j0) * plan.cells_x + static_cast<uint64_t>(i - plan.i0)] = k;
    }
    // Open land: a ground over the cell, as a block's, with nothing built on it.
    open_land_.kind = SurfaceKind::kGround;
    open_land_.cls = BuildingClass::kPerimeter;
    open_land_.building = ~0u;
    open_land_.variant = 2;
    open_land_.grid = 1;
    open_land_.edge_u[0] = open_land_.edge_v[1] = static_cast<float>(kBlockPitchM);
    open_land_.width_m = open_land_.height_m = static_cast<float>(kBlockPitchM);
    open_land_.width_px = open_land_.height_px = static_cast<uint16_t>(plan.block_px);
  }

  // Image rows [y0, y0 + rows), row 0 south; a cell's painter rows run north to south, so each band is painted
  // in the painter's order and copied flipped.
  void paint_rows(uint32_t y0, uint32_t rows, uint32_t* out) const {
    const uint32_t bp = plan_.block_px, width = plan_.width();
    std::vector<uint32_t> band;
    for (uint32_t y = y0; y < y0 + rows;) {
      const uint32_t cj = y / bp, cell_y0 = cj * bp;
      const uint32_t y_end = std::min(y0 + rows, cell_y0 + bp);
      const uint32_t n = y_end - y, first = bp - (y_end - cell_y0);  // painter rows [first, first + n)
      band.resize(uint64_t{bp} * n);
      for (uint32_t ci = 0; ci < plan_.cells_x; ++ci) {
        const uint64_t k = cells_[uint64_t{cj} * plan_.cells_x + ci];
        if (k != kNoBlock) {
          paint_ground_rows(seed_, Stream::kTexture, k, ground_at_scale(city_.surfaces[k], bp), first, band);
        } else {
          const auto i = static_cast<uint32_t>(plan_.i0 + static_cast<int32_t>(ci));
          const auto j = static_cast<uint32_t>(plan_.j0 + static_cast<int32_t>(cj));
          paint_ground_rows(seed_, Stream::kOpenLand, uint64_t{i} << 32 | j, open_land_, first, band);
        }
        for (uint32_t yy = y; yy < y_end; ++yy) {
          const uint32_t painter_row = bp - 1 - (yy - cell_y0);
          std::memcpy(out + uint64_t{yy - y0} * width + uint64_t{ci} * bp,
                      band.data() + uint64_t{painter_row - first} * bp, uint64_t{bp} * sizeof(uint32_t));
        }
      }
      y = y_end;
    }
  }

 private:
  const CityLayout& city_;
  GroundPlan plan_;
  uint64_t seed_;
  std::vector<uint64_t> cells_;  // row-major from the south-west cell: the layout index of its ground
  Surface open_land_{};
};

// The finest level, painted as the baker asks for it (64-row chunks from its threads): no image is held here.
class CityGroundSource : public tile::PageSource {
 public:
  CityGroundSource(const CityLayout& city, const GroundPlan& plan, uint64_t seed, const GroundProgressFn& progress)
      : painter_(city, plan, seed), plan_(plan), progress_(progress) {}

  Extent2D extent() const override { return {plan_.width(), plan_.height()}; }

  Status fill_rows(uint32_t y0, uint32_t rows, uint32_t* out) const override {
    painter_.paint_rows(y0, rows, out);
    // relaxed: a count for the progress bar only; the rows themselves are published by the baker's thread join.
    const uint64_t done = rows_done_.fetch_add(rows, std::memory_order_relaxed) + rows;
    if (progress_) progress_(GroundPhase::kPaint, done, plan_.height());
    return ok_status();
  }

 private:
  CityGroundPainter painter_;
  GroundPlan plan_;
  const GroundProgressFn& progress_;
  mutable std::atomic<uint64_t> rows_done_{0};
};

}  // namespace

Result<GroundPlan> plan_ground(const CityLayout& city, double texel_m) {
  GroundPlan plan;
  bool any = false;
  int32_t i1 = 0, j1 = 0;
  for (const Surface& s : city.surfaces) {
    if (s.kind != SurfaceKind::kGround) continue;
    const auto [i, j] = cell_of(s);
    if (!any) {
      plan.i0 = i1 = i;
      plan.j0 = j1 = j;
      plan.z_m = s.corner[2];
      any = true;
    }
    TS_ASSERT(s.corner[2] == plan.z_m, "block grounds at two heights (%g m and %g m)", s.corner[2], plan.z_m);
    plan.i0 = std::min(plan.i0, i);
    plan.j0 = std::min(plan.j0, j);
    i1 = std::max(i1, i);
    j1 = std::max(j1, j);
  }
  TS_ASSERT(any, "a city without a block");
  plan.cells_x = static_cast<uint32_t>(i1 - plan.i0 + 1);
  plan.cells_y = static_cast<uint32_t>(j1 - plan.j0 + 1);
  const uint32_t cells = std::max(plan.cells_x, plan.cells_y);
  if (texel_m == 0) {
    const auto fine = static_cast<uint32_t>(std::lround(kBlockPitchM / kGroundTexelM));
    plan.block_px = std::max(1u, std::min(fine, kGroundAutoMaxSide / cells));
  } else {
    if (!std::isfinite(texel_m) || texel_m < 0)
      return make_error(ErrorCode::kInvalidArgument, "--ground-texel-m: must be a positive number of metres");
    char what[64];
    std::snprintf(what, sizeof what, "--ground-texel-m %g: ", texel_m);
    const double px = std::round(kBlockPitchM / texel_m);
    if (px < 1 || px > kGroundMaxBlockPx) {
      char why[128];
      std::snprintf(why, sizeof why, "%.4g texels across a %g m block, not 1..%u", kBlockPitchM / texel_m, kBlockPitchM,
                    kGroundMaxBlockPx);
      return make_error(ErrorCode::kInvalidArgument, std::string(what) + why);
    }
    plan.block_px = static_cast<uint32_t>(px);
    if (uint64_t{cells} * plan.block_px > pages::kMaxVirtualExtent)
      return make_error(ErrorCode::kInvalidArgument,
                        std::string(what) + "the city's ground (" + std::to_string(cells) +
                            " blocks across) would be " + std::to_string(uint64_t{cells} * plan.block_px) +
                            " texels a side, more than a page file's " + std::to_string(pages::kMaxVirtualExtent));
  }
  plan.metres_per_texel = kBlockPitchM / plan.block_px;
  return plan;
}

Surface ground_at_scale(const Surface& ground, uint32_t block_px) {
  TS_ASSERT(ground.kind == SurfaceKind::kGround && block_px >= 1 && block_px <= kGroundMaxBlockPx,
            "ground_at_scale: kind %d, %u texels", static_cast<int>(ground.kind), block_px);
  Surface s = ground;
  s.width_px = s.height_px = static_cast<uint16_t>(block_px);
  return s;
}

void paint_city_ground_rows(const CityLayout& city, const GroundPlan& plan, uint64_t seed, uint32_t y0, uint32_t rows,
                            uint32_t* out) {
  CityGroundPainter(city, plan, seed).paint_rows(y0, rows, out);
}

Result<GroundBakeStats> bake_city_ground(const CityLayout& city, const GroundPlan& plan, uint64_t seed,
                                         TexelFormat format, unsigned threads, const std::filesystem::path& out,
                                         const GroundProgressFn& progress) {
  const CityGroundSource source(city, plan, seed, progress);
  tile::BakeOptions opt;
  opt.format = format;
  opt.threads = threads;
  tile::BakeProgress pages_done;
  if (progress) pages_done = [&progress](uint64_t done, uint64_t total) { progress(GroundPhase::kBake, done, total); };
  auto baked = tile::bake_pages(source, opt, out, pages_done);
  if (!baked.ok()) return baked.error();
  return GroundBakeStats{baked->stored_pages, baked->file_bytes, baked->seconds};
}

}  // namespace texstream::gen
