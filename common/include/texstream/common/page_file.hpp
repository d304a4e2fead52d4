#pragma once
// A huge texture cut into a quadtree of uniform pages (seed 002 §3.1, seed 004 §3.1): one file, read one page at
// a time with one exact byte range. Written by texstream-tile, read by the server (page ranges) and the renderer
// (the index: which pages exist, their NoiseValues). Little-endian, like every scene file.
//
//   PageFileHeader (64 bytes)
//   PageIndexEntry[page_slots]     one per page of the full quadtree, absolute order (below); offset 0 = not stored
//   page data                      stored pages back to back in absolute order, page_bytes each
//
// Levels count from the coarsest (seed 004: "mip level 0 at the lowest resolution"): level 0 is one page over
// the whole square of side P << (L - 1), level L - 1 holds the image at 1:1. Level l has 2^l x 2^l pages; the
// absolute index of page (x, y) of level l is (4^l - 1) / 3 + y * 2^l + x. The image sits at the square's
// origin; a page is stored when its P x P interior touches the image at its level (seed 002: "empty tiles are
// not stored"). Every stored page carries a border of B texels of its neighbours on each side (seed 004 §3.3.1.1)
// so that bilinear filtering inside a cache frame never reads another page's texels; beyond the image the
// border clamps to the image's edge texels at that level (or wraps, for a repeating square texture).
// docs/design/pages.md has the reasoning and the limits.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::pages {

inline constexpr uint64_t kPageFileMagic = 0x3130454741505354ull;  // "TSPAGE01"
inline constexpr uint32_t kPageFileVersion = 1;
// Largest square side (2^18 texels): with 128-texel pages 5.6 M index entries (89 MB); bounds every count below.
inline constexpr uint32_t kMaxVirtualExtent = 1u << 18;
inline constexpr uint32_t kMinPageTexels = 8, kMaxPageTexels = 1024;

enum class PageWrap : uint32_t {
  kClamp = 0,   // borders beyond the image repeat its edge texels (a terrain, an orthophoto)
  kRepeat = 1,  // borders wrap around (a square power-of-two texture that tiles)
};

struct PageFileHeader {
  uint64_t magic;
  uint32_t version;
  uint32_t format;  // TexelFormat: rgba8, bc1 or bc3
  uint32_t width;   // the image at the finest level, texels
  uint32_t height;
  uint32_t page_texels;    // P: a page's side without its border, a power of two
  uint32_t border_texels;  // B: border texels on each side (a multiple of 4 for block formats), B <= P / 2
  uint32_t levels;         // L
  uint32_t wrap;           // PageWrap
  uint64_t stored_pages;
  uint64_t index_offset;  // sizeof(PageFileHeader)
  uint64_t data_offset;   // index_offset + page_slots * sizeof(PageIndexEntry), rounded up to 4096
};
static_assert(sizeof(PageFileHeader) == 64);

struct PageIndexEntry {
  uint64_t offset;  // of the page's bytes in the file; 0 when the page is not stored
  uint32_t bytes;   // page_bytes for a stored page, 0 otherwise
  float noise;      // seed 004 §3.3.1.2: luminance RMSE (0-255) of the page against its parent's quarter scaled
                    // up; for the root, against the page's mean colour (what the City Colormap shows first)
};
static_assert(sizeof(PageIndexEntry) == 16);

struct PageId {
  uint32_t level = 0;
  uint32_t x = 0;
  uint32_t y = 0;
  bool operator==(const PageId&) const = default;
};

// The quadtree's shape, from the header's numbers alone: no I/O.
struct PageGeometry {
  TexelFormat format = TexelFormat::kRgba8;
  uint32_t width = 0, height = 0;
  uint32_t page_texels = 0, border_texels = 0;
  uint32_t levels = 0;
  PageWrap wrap = PageWrap::kClamp;

  // The fewest levels whose square holds the image (at least one).
  static uint32_t levels_for(uint32_t width, uint32_t height, uint32_t page_texels);
  // Checks a geometry a user or a file gave; the error names `what` and the field.
  static Result<PageGeometry> make(TexelFormat format, uint32_t width, uint32_t height, uint32_t page_texels,
                                   uint32_t border_texels, PageWrap wrap, const std::string& what);

  uint32_t virtual_extent() const { return page_texels << (levels - 1); }
  uint32_t stored_side() const { return page_texels + 2 * border_texels; }
  uint64_t page_bytes() const { return mip_bytes(format, Extent2D{stored_side(), stored_side()}); }
  uint64_t page_slots() const { return first_slot(levels); }
  // Slots of levels [0, level): (4^level - 1) / 3.
  static uint64_t first_slot(uint32_t level) { return ((uint64_t{1} << (2 * level)) - 1) / 3; }
  uint64_t slot(PageId p) const { return first_slot(p.level) + uint64_t{p.y} * (uint64_t{1} << p.level) + p.x; }
  PageId page_of_slot(uint64_t slot) const;
  // The image's extent at `level` in texels: every texel of the level that covers part of the image.
  Extent2D image_extent(uint32_t level) const;
  // Whether the page's interior touches the image (the baker stores exactly these pages).
  bool in_image(PageId p) const;
  uint64_t pages_in_image() const;
};

// A page file's header and index, checked: every field, every entry's range inside the file and of the page's
// size, every stored page's parent stored (ancestors are the fallback of every pixel), the root stored.
class PageFile {
 public:
  // Reads `bytes.size()` bytes at `offset` and returns how many it read (a short count is an error here).
  using ReadAt = std::function<Result<uint64_t>(std::span<std::byte> bytes, uint64_t offset)>;

  // `name` (the path or URL) goes into every error.
  static Result<PageFile> load(const ReadAt& read, uint64_t file_size, const std::string& name);
  static Result<PageFile> open(const std::filesystem::path& path);

  const PageGeometry& geometry() const { return geometry_; }
  const PageFileHeader& header() const { return header_; }
  uint64_t stored_pages() const { return header_.stored_pages; }
  // The page's byte range; nullopt when it is not stored (or out of range).
  std::optional<PageIndexEntry> entry(PageId p) const;
  bool stored(PageId p) const { return entry(p).has_value(); }
  float noise(PageId p) const;
  // The mean NoiseValue of the stored pages (seed 004 §4.3.1's NoiseValueSkipping threshold).
  double mean_noise() const { return mean_noise_; }

 private:
  std::string name_;
  PageFileHeader header_{};
  PageGeometry geometry_;
  std::vector<PageIndexEntry> index_;
  double mean_noise_ = 0;
};

// The header of a file with this geometry (offsets filled in), for writers.
PageFileHeader make_page_file_header(const PageGeometry& g, uint64_t stored_pages);

}  // namespace texstream::pages
