#include "page_baker.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <mutex>
#include <thread>

#include "bc1_encoder.hpp"
#include "mip_chain.hpp"

namespace texstream::tile {

using pages::PageGeometry;
using pages::PageId;
using pages::PageWrap;

namespace {

unsigned thread_count(unsigned wanted) { return wanted ? wanted : std::max(1u, std::thread::hardware_concurrency()); }

// Runs fn(i) for i in [0, n) on `threads` threads, each taking the next index.
template <class Fn>
void parallel_for(uint64_t n, unsigned threads, Fn&& fn) {
  std::atomic<uint64_t> next{0};
  auto work = [&] {
    for (uint64_t i = next++; i < n; i = next++) fn(i);
  };
  std::vector<std::thread> pool;
  const unsigned extra = static_cast<unsigned>(std::min<uint64_t>(threads, std::max<uint64_t>(n, 1))) - 1;
  for (unsigned t = 0; t < extra; ++t) pool.emplace_back(work);
  work();
  for (auto& t : pool) t.join();
}

int64_t wrap_or_clamp(int64_t v, uint32_t extent, PageWrap wrap) {
  if (wrap == PageWrap::kRepeat) {
    const int64_t e = extent;
    return ((v % e) + e) % e;
  }
  return std::clamp<int64_t>(v, 0, int64_t{extent} - 1);
}

double luminance(uint32_t rgba) {
  return 0.2126 * (rgba & 0xffu) + 0.7152 * ((rgba >> 8) & 0xffu) + 0.0722 * ((rgba >> 16) & 0xffu);
}

Error io_error(const std::filesystem::path& p, const char* what) {
  return make_error(ErrorCode::kIo, p.string() + ": " + what + ": " + std::strerror(errno));
}

Status pwrite_all(int fd, const void* data, uint64_t bytes, uint64_t offset, const std::filesystem::path& p) {
  const auto* b = static_cast<const std::byte*>(data);
  uint64_t done = 0;
  while (done < bytes) {
    const ssize_t n = ::pwrite(fd, b + done, bytes - done, static_cast<off_t>(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return io_error(p, "write failed");
    done += static_cast<uint64_t>(n);
  }
  return ok_status();
}

Result<LevelImage> finest_level(const PageSource& source, const PageGeometry& g, unsigned threads) {
  LevelImage level;
  level.width = g.width;
  level.height = g.height;
  level.texels.resize(uint64_t{g.width} * g.height);
  constexpr uint32_t kRows = 64;
  const uint32_t chunks = (g.height + kRows - 1) / kRows;
  std::mutex mutex;
  std::optional<Error> failure;
  parallel_for(chunks, threads, [&](uint64_t c) {
    const uint32_t y0 = static_cast<uint32_t>(c) * kRows, rows = std::min(kRows, g.height - y0);
    Status st = source.fill_rows(y0, rows, level.texels.data() + uint64_t{y0} * g.width);
    if (!st.ok()) {
      std::lock_guard lock(mutex);
      if (!failure) failure = st.error();
    }
  });
  if (failure) return *failure;
  return level;
}

}  // namespace

uint32_t LevelImage::at(int64_t x, int64_t y, PageWrap wrap) const {
  return texels[static_cast<uint64_t>(wrap_or_clamp(y, height, wrap)) * width +
                static_cast<uint64_t>(wrap_or_clamp(x, width, wrap))];
}

LevelImage downsample(const LevelImage& finer, PageWrap wrap, unsigned threads) {
  LevelImage out;
  out.width = (finer.width + 1) / 2;
  out.height = (finer.height + 1) / 2;
  out.texels.resize(uint64_t{out.width} * out.height);
  parallel_for(out.height, thread_count(threads), [&](uint64_t row) {
    const auto y = static_cast<int64_t>(row);
    for (uint32_t x = 0; x < out.width; ++x) {
      const uint32_t t[4] = {finer.at(2 * x, 2 * y, wrap), finer.at(2 * x + 1, 2 * y, wrap),
                             finer.at(2 * x, 2 * y + 1, wrap), finer.at(2 * x + 1, 2 * y + 1, wrap)};
      uint32_t v = 0;
      for (int c = 0; c < 3; ++c) {
        float sum = 0;
        for (uint32_t s : t) sum += gen::srgb8_to_linear(static_cast<uint8_t>(s >> (8 * c)));
        v |= uint32_t{gen::linear_to_srgb8(sum * 0.25f)} << (8 * c);
      }
      uint32_t alpha = 0;
      for (uint32_t s : t) alpha += s >> 24;
      v |= ((alpha + 2) / 4) << 24;
      out.texels[row * out.width + x] = v;
    }
  });
  return out;
}

void cut_page(const PageGeometry& g, const LevelImage& level, PageId p, std::span<uint32_t> out) {
  const uint32_t side = g.stored_side();
  TS_ASSERT(out.size() == uint64_t{side} * side, "cut_page: %zu texels for a %u-texel page", out.size(), side);
  const int64_t x0 = int64_t{p.x} * g.page_texels - g.border_texels;
  const int64_t y0 = int64_t{p.y} * g.page_texels - g.border_texels;
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) out[uint64_t{j} * side + i] = level.at(x0 + i, y0 + j, g.wrap);
}

float page_noise(const PageGeometry& g, const LevelImage& level, const LevelImage* parent, PageId p) {
  const uint32_t P = g.page_texels;
  const uint32_t x_end = std::min<uint32_t>(P, level.width - std::min(level.width, p.x * P));
  const uint32_t y_end = std::min<uint32_t>(P, level.height - std::min(level.height, p.y * P));
  if (x_end == 0 || y_end == 0) return 0;
  double sum = 0, sum_sq = 0;
  for (uint32_t j = 0; j < y_end; ++j) {
    for (uint32_t i = 0; i < x_end; ++i) {
      const int64_t cx = int64_t{p.x} * P + i, cy = int64_t{p.y} * P + j;
      const double child = luminance(level.at(cx, cy, g.wrap));
      if (!parent) {
        sum += child;
        sum_sq += child * child;
        continue;
      }
      // The child texel's centre in the parent's texel space, bilinear between its four nearest parent texels.
      const double u = (static_cast<double>(cx) + 0.5) / 2 - 0.5, v = (static_cast<double>(cy) + 0.5) / 2 - 0.5;
      const double fu = std::floor(u), fv = std::floor(v), au = u - fu, av = v - fv;
      const auto px = static_cast<int64_t>(fu), py = static_cast<int64_t>(fv);
      const double up = (1 - av) * ((1 - au) * luminance(parent->at(px, py, g.wrap)) +
                                    au * luminance(parent->at(px + 1, py, g.wrap))) +
                        av * ((1 - au) * luminance(parent->at(px, py + 1, g.wrap)) +
                              au * luminance(parent->at(px + 1, py + 1, g.wrap)));
      sum_sq += (child - up) * (child - up);
    }
  }
  const double n = static_cast<double>(x_end) * y_end;
  if (!parent) return static_cast<float>(std::sqrt(std::max(0.0, sum_sq / n - (sum / n) * (sum / n))));
  return static_cast<float>(std::sqrt(sum_sq / n));
}

Result<std::vector<LevelImage>> build_pyramid(const PageSource& source, const PageGeometry& g) {
  auto finest = finest_level(source, g, thread_count(0));
  if (!finest.ok()) return finest.error();
  std::vector<LevelImage> levels(g.levels);
  levels[g.levels - 1] = std::move(finest.value());
  for (uint32_t l = g.levels - 1; l > 0; --l) levels[l - 1] = downsample(levels[l], g.wrap, 0);
  return levels;
}

Result<BakeStats> bake_pages(const PageSource& source, const BakeOptions& opt, const std::filesystem::path& out,
                             const BakeProgress& progress) {
  const auto t0 = std::chrono::steady_clock::now();
  const Extent2D e = source.extent();
  auto geometry =
      PageGeometry::make(opt.format, e.width, e.height, opt.page_texels, opt.border_texels, opt.wrap, out.string());
  if (!geometry.ok()) return geometry.error();
  const PageGeometry& g = *geometry;
  const unsigned threads = thread_count(opt.threads);

  // Offsets first: stored pages lie in absolute order, so coarse levels come first in the file (seed 004 §3.2.5.1).
  const uint64_t stored = g.pages_in_image();
  const pages::PageFileHeader header = pages::make_page_file_header(g, stored);
  std::vector<pages::PageIndexEntry> index(g.page_slots(), pages::PageIndexEntry{0, 0, 0.0f});
  uint64_t next_offset = header.data_offset;
  const uint64_t page_bytes = g.page_bytes();
  for (uint64_t s = 0; s < index.size(); ++s) {
    if (!g.in_image(g.page_of_slot(s))) continue;
    index[s].offset = next_offset;
    index[s].bytes = static_cast<uint32_t>(page_bytes);
    next_offset += page_bytes;
  }
  const uint64_t file_bytes = next_offset;

  const std::filesystem::path partial = out.string() + ".partial";
  const int fd = ::open(partial.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return io_error(partial, "cannot create");
  bool keep = false;
  struct Cleanup {
    int fd;
    const std::filesystem::path& path;
    const bool& keep;
    ~Cleanup() {
      ::close(fd);
      if (!keep) ::unlink(path.c_str());
    }
  } cleanup{fd, partial, keep};
  if (::ftruncate(fd, static_cast<off_t>(file_bytes)) != 0) return io_error(partial, "cannot size");

  auto finest = finest_level(source, g, threads);
  if (!finest.ok()) return finest.error();
  LevelImage level = std::move(finest.value());
  BakeStats stats;
  stats.geometry = g;
  stats.stored_pages = stored;
  stats.file_bytes = file_bytes;
  std::atomic<uint64_t> done{0};
  std::mutex mutex;
  std::optional<Error> failure;
  double noise_sum = 0;
  for (uint32_t l = g.levels; l-- > 0;) {
    LevelImage parent;
    if (l > 0) parent = downsample(level, g.wrap, threads);
    stats.peak_level_bytes =
        std::max(stats.peak_level_bytes, (level.texels.size() + parent.texels.size()) * sizeof(uint32_t));
    const Extent2D ext = g.image_extent(l);
    const uint32_t across = (ext.width + g.page_texels - 1) / g.page_texels;
    const uint32_t down = (ext.height + g.page_texels - 1) / g.page_texels;
    parallel_for(uint64_t{across} * down, threads, [&](uint64_t k) {
      const PageId p{l, static_cast<uint32_t>(k % across), static_cast<uint32_t>(k / across)};
      std::vector<uint32_t> texels(uint64_t{g.stored_side()} * g.stored_side());
      cut_page(g, level, p, texels);
      const float noise = page_noise(g, level, l > 0 ? &parent : nullptr, p);
      std::vector<uint8_t> encoded(page_bytes);
      if (g.format == TexelFormat::kBc1)
        gen::encode_bc1(texels.data(), g.stored_side(), g.stored_side(), encoded);
      else if (g.format == TexelFormat::kBc3)
        gen::encode_bc3(texels.data(), g.stored_side(), g.stored_side(), encoded);
      else
        std::memcpy(encoded.data(), texels.data(), page_bytes);
      pages::PageIndexEntry& entry = index[g.slot(p)];
      Status st = pwrite_all(fd, encoded.data(), page_bytes, entry.offset, partial);
      std::lock_guard lock(mutex);
      entry.noise = noise;
      noise_sum += static_cast<double>(noise);
      if (!st.ok() && !failure) failure = st.error();
      if (progress) progress(++done, stored);
    });
    if (failure) return *failure;
    level = std::move(parent);
  }
  TS_TRY(pwrite_all(fd, index.data(), index.size() * sizeof(pages::PageIndexEntry), header.index_offset, partial));
  TS_TRY(pwrite_all(fd, &header, sizeof header, 0, partial));
  if (::fsync(fd) != 0) return io_error(partial, "cannot sync");
  std::error_code ec;
  std::filesystem::rename(partial, out, ec);
  if (ec)
    return make_error(ErrorCode::kIo, out.string() + ": cannot rename the finished bake into place: " + ec.message());
  keep = true;
  stats.mean_noise = noise_sum / static_cast<double>(stored);
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return stats;
}

}  // namespace texstream::tile
