#include "texstream/common/page_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>

namespace texstream::pages {

namespace {

Error corrupt(const std::string& what, const std::string& why) {
  return make_error(ErrorCode::kCorrupt, what + ": page file " + why);
}

uint64_t round_up(uint64_t v, uint64_t to) { return (v + to - 1) / to * to; }

}  // namespace

uint32_t PageGeometry::levels_for(uint32_t width, uint32_t height, uint32_t page_texels) {
  if (page_texels == 0) return 1;  // make() refuses it; no endless loop here either
  uint32_t levels = 1;
  while (uint64_t{page_texels} << (levels - 1) < std::max(width, height)) ++levels;
  return levels;
}

Result<PageGeometry> PageGeometry::make(TexelFormat format, uint32_t width, uint32_t height, uint32_t page_texels,
                                        uint32_t border_texels, PageWrap wrap, const std::string& what) {
  auto bad = [&](const std::string& why) { return make_error(ErrorCode::kInvalidArgument, what + ": " + why); };
  if (format != TexelFormat::kRgba8 && format != TexelFormat::kBc1 && format != TexelFormat::kBc3)
    return bad("format " + std::string(to_string(format)) + " cannot be baked into pages (rgba8, bc1 or bc3)");
  if (width == 0 || height == 0 || width > kMaxVirtualExtent || height > kMaxVirtualExtent)
    return bad("extent " + std::to_string(width) + "x" + std::to_string(height) + " is not within 1.." +
               std::to_string(kMaxVirtualExtent));
  if (!std::has_single_bit(page_texels) || page_texels < kMinPageTexels || page_texels > kMaxPageTexels)
    return bad("page_texels " + std::to_string(page_texels) + " is not a power of two in " +
               std::to_string(kMinPageTexels) + ".." + std::to_string(kMaxPageTexels));
  if (border_texels > page_texels / 2)
    return bad("border_texels " + std::to_string(border_texels) + " is more than half a page (" +
               std::to_string(page_texels) + ")");
  if (is_block_compressed(format) && border_texels % 4 != 0)
    return bad("border_texels " + std::to_string(border_texels) + " is not a multiple of 4, which " +
               std::string(to_string(format)) + " blocks need");
  if (wrap != PageWrap::kClamp && wrap != PageWrap::kRepeat)
    return bad("wrap " + std::to_string(static_cast<uint32_t>(wrap)) + " is neither clamp (0) nor repeat (1)");
  PageGeometry g;
  g.format = format;
  g.width = width;
  g.height = height;
  g.page_texels = page_texels;
  g.border_texels = border_texels;
  g.levels = levels_for(width, height, page_texels);
  g.wrap = wrap;
  if (uint64_t{page_texels} << (g.levels - 1) > kMaxVirtualExtent)
    return bad("extent " + std::to_string(width) + "x" + std::to_string(height) + " needs a square of side " +
               std::to_string(uint64_t{page_texels} << (g.levels - 1)) + ", more than " +
               std::to_string(kMaxVirtualExtent));
  // A repeating texture wraps with the image's own period; the square's levels halve it only when they are equal.
  if (wrap == PageWrap::kRepeat && (width != height || width != g.virtual_extent()))
    return bad("wrap repeat needs a square power-of-two image of at least one page, not " + std::to_string(width) +
               "x" + std::to_string(height));
  return g;
}

PageId PageGeometry::page_of_slot(uint64_t slot) const {
  uint32_t level = 0;
  while (level + 1 < levels && first_slot(level + 1) <= slot) ++level;
  const uint64_t within = slot - first_slot(level);
  return {level, static_cast<uint32_t>(within & ((uint64_t{1} << level) - 1)), static_cast<uint32_t>(within >> level)};
}

Extent2D PageGeometry::image_extent(uint32_t level) const {
  const uint32_t shift = levels - 1 - level;
  const uint64_t div = uint64_t{1} << shift;
  return {static_cast<uint32_t>((width + div - 1) / div), static_cast<uint32_t>((height + div - 1) / div)};
}

bool PageGeometry::in_image(PageId p) const {
  if (p.level >= levels) return false;
  const Extent2D e = image_extent(p.level);
  return uint64_t{p.x} * page_texels < e.width && uint64_t{p.y} * page_texels < e.height;
}

uint64_t PageGeometry::pages_in_image() const {
  uint64_t n = 0;
  for (uint32_t l = 0; l < levels; ++l) {
    const Extent2D e = image_extent(l);
    n += uint64_t{(e.width + page_texels - 1) / page_texels} * ((e.height + page_texels - 1) / page_texels);
  }
  return n;
}

PageFileHeader make_page_file_header(const PageGeometry& g, uint64_t stored_pages) {
  PageFileHeader h{};
  h.magic = kPageFileMagic;
  h.version = kPageFileVersion;
  h.format = static_cast<uint32_t>(g.format);
  h.width = g.width;
  h.height = g.height;
  h.page_texels = g.page_texels;
  h.border_texels = g.border_texels;
  h.levels = g.levels;
  h.wrap = static_cast<uint32_t>(g.wrap);
  h.stored_pages = stored_pages;
  h.index_offset = sizeof(PageFileHeader);
  h.data_offset = round_up(h.index_offset + g.page_slots() * sizeof(PageIndexEntry), 4096);
  return h;
}

Result<PageFile> PageFile::load(const ReadAt& read, uint64_t file_size, const std::string& name) {
  PageFile f;
  f.name_ = name;
  if (file_size < sizeof(PageFileHeader))
    return corrupt(name, "is " + std::to_string(file_size) + " bytes, shorter than its 64-byte header");
  auto got = read(std::as_writable_bytes(std::span(&f.header_, 1)), 0);
  if (!got.ok()) return got.error();
  const PageFileHeader& h = f.header_;
  if (h.magic != kPageFileMagic) return corrupt(name, "field 'magic' is not TSPAGE01");
  if (h.version != kPageFileVersion)
    return corrupt(name, "field 'version' is " + std::to_string(h.version) + ", this build reads " +
                             std::to_string(kPageFileVersion));
  const auto format = texel_format_from_raw(h.format);
  if (!format) return corrupt(name, "field 'format' is " + std::to_string(h.format) + ", no texel format");
  auto g = PageGeometry::make(*format, h.width, h.height, h.page_texels, h.border_texels, static_cast<PageWrap>(h.wrap),
                              name + ": page file header");
  if (!g.ok()) return make_error(ErrorCode::kCorrupt, g.error().message);
  f.geometry_ = *g;
  if (h.levels != g->levels)
    return corrupt(name, "field 'levels' is " + std::to_string(h.levels) + ", the extent and page size give " +
                             std::to_string(g->levels));
  const PageFileHeader want = make_page_file_header(*g, h.stored_pages);
  if (h.index_offset != want.index_offset)
    return corrupt(name, "field 'index_offset' is " + std::to_string(h.index_offset) + ", not " +
                             std::to_string(want.index_offset));
  if (h.data_offset != want.data_offset)
    return corrupt(
        name, "field 'data_offset' is " + std::to_string(h.data_offset) + ", not " + std::to_string(want.data_offset));
  const uint64_t page_bytes = g->page_bytes();
  if (h.stored_pages == 0 || h.stored_pages > g->pages_in_image())
    return corrupt(name, "field 'stored_pages' is " + std::to_string(h.stored_pages) + ", not within 1.." +
                             std::to_string(g->pages_in_image()) + " (the pages that touch the image)");
  if (file_size < h.data_offset || (file_size - h.data_offset) / page_bytes < h.stored_pages)
    return corrupt(name, "is " + std::to_string(file_size) + " bytes, too short for " + std::to_string(h.stored_pages) +
                             " pages of " + std::to_string(page_bytes) + " bytes after the index");
  f.index_.resize(g->page_slots());
  got = read(std::as_writable_bytes(std::span(f.index_)), h.index_offset);
  if (!got.ok()) return got.error();

  uint64_t stored = 0;
  double noise_sum = 0;
  for (uint64_t s = 0; s < f.index_.size(); ++s) {
    const PageIndexEntry& e = f.index_[s];
    auto at = [&] {
      const PageId p = g->page_of_slot(s);
      return "index entry " + std::to_string(s) + " (level " + std::to_string(p.level) + " page " +
             std::to_string(p.x) + "," + std::to_string(p.y) + ")";
    };
    if (!std::isfinite(e.noise) || e.noise < 0)
      return corrupt(name, at() + " field 'noise' is " + std::to_string(e.noise) + ", not a finite value >= 0");
    if (e.offset == 0) {
      if (e.bytes != 0) return corrupt(name, at() + " is not stored but field 'bytes' is " + std::to_string(e.bytes));
      if (s == 0) return corrupt(name, "does not store the root page (level 0), the fallback of every texel");
      continue;
    }
    const PageId p = g->page_of_slot(s);
    if (!g->in_image(p)) return corrupt(name, at() + " is stored but lies outside the image");
    if (e.bytes != page_bytes)
      return corrupt(name, at() + " field 'bytes' is " + std::to_string(e.bytes) + ", not the page size " +
                               std::to_string(page_bytes));
    if (e.offset < h.data_offset || e.offset > file_size || file_size - e.offset < page_bytes)
      return corrupt(name, at() + " field 'offset' " + std::to_string(e.offset) + " is outside the page data [" +
                               std::to_string(h.data_offset) + ", " + std::to_string(file_size) + ")");
    if (p.level > 0 && f.index_[g->slot({p.level - 1, p.x / 2, p.y / 2})].offset == 0)
      return corrupt(name, at() + " is stored but its parent is not: every page needs its ancestors");
    ++stored;
    noise_sum += static_cast<double>(e.noise);
  }
  if (stored != h.stored_pages)
    return corrupt(name, "field 'stored_pages' is " + std::to_string(h.stored_pages) + " but the index stores " +
                             std::to_string(stored));
  f.mean_noise_ = noise_sum / static_cast<double>(stored);
  return f;
}

Result<PageFile> PageFile::open(const std::filesystem::path& path) {
  const std::string name = path.string();
  const int fd = ::open(name.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0)
    return make_error(errno == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo,
                      name + ": cannot open: " + std::strerror(errno));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  const off_t size = ::lseek(fd, 0, SEEK_END);
  if (size < 0) return make_error(ErrorCode::kIo, name + ": cannot seek: " + std::strerror(errno));
  const ReadAt read = [&](std::span<std::byte> out, uint64_t offset) -> Result<uint64_t> {
    uint64_t done = 0;
    while (done < out.size()) {
      const ssize_t n = ::pread(fd, out.data() + done, out.size() - done, static_cast<off_t>(offset + done));
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) return make_error(ErrorCode::kIo, name + ": read failed: " + std::strerror(errno));
      if (n == 0) return corrupt(name, "ended at byte " + std::to_string(offset + done) + " in the middle of a read");
      done += static_cast<uint64_t>(n);
    }
    return done;
  };
  return load(read, static_cast<uint64_t>(size), name);
}

std::optional<PageIndexEntry> PageFile::entry(PageId p) const {
  if (p.level >= geometry_.levels) return std::nullopt;
  const uint64_t side = uint64_t{1} << p.level;
  if (p.x >= side || p.y >= side) return std::nullopt;
  const PageIndexEntry& e = index_[geometry_.slot(p)];
  if (e.offset == 0) return std::nullopt;
  return e;
}

float PageFile::noise(PageId p) const {
  if (p.level >= geometry_.levels) return 0;
  const uint64_t side = uint64_t{1} << p.level;
  if (p.x >= side || p.y >= side) return 0;
  return index_[geometry_.slot(p)].noise;
}

}  // namespace texstream::pages
