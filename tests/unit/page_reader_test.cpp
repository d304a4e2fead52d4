// The server's page reads (texture_server/…/load/page_reader.hpp): every stored page byte for byte as the file
// holds it, through the local tier, the slow-storage emulation and the disk cache; one read of exactly the page's
// bytes per page (read amplification 1 beyond the index, counted at the origin); a second pass through the disk
// cache never touches the origin; pages that are not stored and damaged files are named.
#include <gtest/gtest.h>

#include <atomic>
#include <fstream>

#include "page_baker.hpp"
#include "test_temp_dir.hpp"
#include "texstream/server/load/page_reader.hpp"
#include "texstream/server/storage/caching_storage.hpp"
#include "texstream/server/storage/counting_storage.hpp"
#include "texstream/server/storage/disk_cache.hpp"
#include "texstream/server/storage/posix_storage.hpp"
#include "texstream/server/storage/slow_storage.hpp"

namespace texstream::server {
namespace {

std::vector<std::byte> file_bytes(const std::filesystem::path& p) {
  std::vector<std::byte> b(std::filesystem::file_size(p));
  std::ifstream(p, std::ios::binary).read(reinterpret_cast<char*>(b.data()), static_cast<std::streamsize>(b.size()));
  return b;
}

// Reads every stored page and checks it against the file's bytes; returns the pages read.
uint64_t read_all(PageReader& r, const std::vector<std::byte>& whole) {
  const auto& g = r.file().geometry();
  std::vector<std::byte> page(g.page_bytes());
  uint64_t n = 0;
  for (uint64_t s = 0; s < g.page_slots(); ++s) {
    const auto p = g.page_of_slot(s);
    const auto e = r.file().entry(p);
    if (!e) continue;
    auto got = r.read(p, page);
    EXPECT_TRUE(got.ok()) << got.error().message;
    EXPECT_EQ(got.value(), g.page_bytes());
    EXPECT_TRUE(std::equal(page.begin(), page.end(), whole.begin() + static_cast<ptrdiff_t>(e->offset)))
        << "level " << p.level << " page " << p.x << "," << p.y;
    ++n;
  }
  return n;
}

class PageReaderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::fresh_test_dir("page_reader");
    std::filesystem::create_directories(dir_ / "scene");
    auto ground = tile::make_painted_ground(600, 450, 0.5, 5);
    tile::BakeOptions opt;
    opt.page_texels = 64;
    ASSERT_TRUE(tile::bake_pages(*ground, opt, dir_ / "scene" / "ground.tspages").ok());
    whole_ = file_bytes(dir_ / "scene" / "ground.tspages");
  }
  std::filesystem::path dir_;
  std::vector<std::byte> whole_;
};

TEST_F(PageReaderTest, OneExactReadPerPageLocally) {
  PosixStorage posix;
  CountingStorage origin(posix);
  auto r = PageReader::open(origin, (dir_ / "scene" / "ground.tspages").string());
  ASSERT_TRUE(r.ok()) << r.error().message;
  const uint64_t index_reads = origin.reads(), index_bytes = origin.bytes();
  EXPECT_EQ(index_reads, 2u);  // header, index
  EXPECT_EQ(index_bytes, r.value()->index_bytes());
  const uint64_t pages = read_all(*r.value(), whole_);
  EXPECT_EQ(pages, r.value()->file().stored_pages());
  EXPECT_EQ(origin.reads() - index_reads, pages);
  const double amp =
      static_cast<double>(origin.bytes() - index_bytes) / static_cast<double>(r.value()->page_bytes_read());
  EXPECT_EQ(amp, 1.0);
}

TEST_F(PageReaderTest, ThroughSlowStorageAndTheDiskCacheTheSecondPassStaysOffTheOrigin) {
  PosixStorage posix;
  CountingStorage origin(posix);
  SlowStorageParams slow;
  slow.latency_ms = 0.2;
  SlowStorage slowed(origin, slow);
  auto cache = DiskCache::open(dir_ / "disk_cache", 64ull << 20, DiskCachePolicy::kLru);
  ASSERT_TRUE(cache.ok()) << cache.error().message;
  CachingStorage caching(slowed, *cache.value(), dir_ / "scene");
  const std::string path = (dir_ / "scene" / "ground.tspages").string();
  {
    auto r = PageReader::open(caching, path);
    ASSERT_TRUE(r.ok()) << r.error().message;
    const uint64_t pages = read_all(*r.value(), whole_);
    EXPECT_EQ(origin.bytes(), r.value()->index_bytes() + pages * r.value()->file().geometry().page_bytes());
  }
  const uint64_t after_first = origin.bytes();
  auto r = PageReader::open(caching, path);
  ASSERT_TRUE(r.ok()) << r.error().message;
  read_all(*r.value(), whole_);
  EXPECT_EQ(origin.bytes(), after_first) << "the second pass read the origin again";
  EXPECT_GT(caching.counters().bytes_from_disk_cache.load(), r.value()->page_bytes_read());
}

TEST_F(PageReaderTest, PagesNotStoredAndDamagedFilesAreNamed) {
  PosixStorage posix;
  const std::string path = (dir_ / "scene" / "ground.tspages").string();
  auto r = PageReader::open(posix, path);
  ASSERT_TRUE(r.ok());
  std::vector<std::byte> page(r.value()->file().geometry().page_bytes());
  const uint32_t top = r.value()->file().geometry().levels - 1;
  auto missing = r.value()->read({top, (1u << top) - 1, 0}, page);  // 600 x 450 in a 1024 square: right column empty
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
  EXPECT_NE(missing.error().message.find(path + ": level " + std::to_string(top) + " page 15,0"), std::string::npos)
      << missing.error().message;
  std::vector<std::byte> small(16);
  EXPECT_FALSE(r.value()->read({0, 0, 0}, small).ok());
  // Truncated in the page data: refused at open, naming the file.
  std::filesystem::resize_file(path, whole_.size() - 1000);
  auto cut = PageReader::open(posix, path);
  ASSERT_FALSE(cut.ok());
  EXPECT_NE(cut.error().message.find(path), std::string::npos);
  EXPECT_NE(cut.error().message.find("too short"), std::string::npos) << cut.error().message;
}

}  // namespace
}  // namespace texstream::server
