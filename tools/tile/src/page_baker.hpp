#pragma once
// texstream-tile's engine: one huge image -> a page file (common/page_file.hpp): every level of its pyramid cut
// into uniform pages with borders, pages outside the image not stored, each page's NoiseValue beside it
// (seed 004 §3.3.1). A library so that tests and texstream-bench bake in-process. docs/design/pages.md.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <span>
#include <vector>

#include "texstream/common/page_file.hpp"
#include "texstream/common/result.hpp"

namespace texstream::tile {

// Where the finest level comes from. fill_rows is called from several threads at once, with disjoint rows.
class PageSource {
 public:
  virtual ~PageSource() = default;
  virtual Extent2D extent() const = 0;
  // Rows [y0, y0 + rows) of the image, extent().width texels each, sRGB RGBA8 with R in the low byte.
  virtual Status fill_rows(uint32_t y0, uint32_t rows, uint32_t* out) const = 0;
};

// One level of the pyramid in memory: the texels of the level that cover the image (PageGeometry::image_extent).
struct LevelImage {
  uint32_t width = 0, height = 0;
  std::vector<uint32_t> texels;
  // The texel at (x, y) of the level, any x and y: beyond the image clamped to its edge, or wrapped.
  uint32_t at(int64_t x, int64_t y, pages::PageWrap wrap) const;
};

// The next coarser level: each texel the linear-light mean of its 2x2 children (sRGB decoded, averaged, encoded
// again, as texstream-gen's mips), the children beyond the image clamped as LevelImage::at does.
LevelImage downsample(const LevelImage& finer, pages::PageWrap wrap, unsigned threads);

// A stored page's texels (stored_side()^2, row-major) from its level.
void cut_page(const pages::PageGeometry& g, const LevelImage& level, pages::PageId p, std::span<uint32_t> out);

// Seed 004 §3.3.1.2: the luminance RMSE between the page's interior texels inside the image and its parent's
// quarter scaled up (bilinear); for the root (parent == nullptr) the luminance's deviation from its mean.
float page_noise(const pages::PageGeometry& g, const LevelImage& level, const LevelImage* parent, pages::PageId p);

struct BakeOptions {
  TexelFormat format = TexelFormat::kBc1;
  uint32_t page_texels = 128;
  uint32_t border_texels = 4;
  pages::PageWrap wrap = pages::PageWrap::kClamp;
  unsigned threads = 0;  // 0: every core
};

struct BakeStats {
  pages::PageGeometry geometry;
  uint64_t stored_pages = 0;
  uint64_t file_bytes = 0;
  uint64_t peak_level_bytes = 0;  // the two levels held at once (the finest and the next)
  double mean_noise = 0;
  double seconds = 0;
};

using BakeProgress = std::function<void(uint64_t pages_done, uint64_t pages_total)>;

// Writes `out` through a temporary file renamed into place: a failed bake leaves no partial file behind.
Result<BakeStats> bake_pages(const PageSource& source, const BakeOptions& opt, const std::filesystem::path& out,
                             const BakeProgress& progress = {});

// The whole pyramid of a small source, finest level last (tests compare pages against it).
Result<std::vector<LevelImage>> build_pyramid(const PageSource& source, const pages::PageGeometry& g);

// An image file (PNG, JPEG, TGA, BMP, PSD, GIF, HDR, PIC, PNM through stb_image), decoded whole into memory.
Result<std::unique_ptr<PageSource>> open_image_source(const std::filesystem::path& path);

// An orthophoto-like ground seen from above: street grid with markings, roofs, courtyards, parks with trees, all
// a pure function of the texel (any tile of it can be painted alone), `metres_per_texel` at the finest level.
std::unique_ptr<PageSource> make_painted_ground(uint32_t width, uint32_t height, double metres_per_texel,
                                                uint64_t seed);

}  // namespace texstream::tile
