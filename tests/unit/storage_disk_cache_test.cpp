// Disk cache (issue 4): entries survive a restart through the on-disk index; a corrupt or torn entry is
// dropped and never served; a damaged index line ends the replay there; LRU and FIFO evict in their orders
// (also across a restart); a second owner of the folder is refused. Files only: no network, shm or clock.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "test_temp_dir.hpp"
#include "texstream/server/disk_cache.hpp"

namespace fs = std::filesystem;

namespace texstream::server {
namespace {

class DiskCacheTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = test::fresh_test_dir("texstream_disk_cache", /*create=*/false); }
  void TearDown() override { fs::remove_all(dir_); }

  std::unique_ptr<DiskCache> open(uint64_t budget = 1 << 20, DiskCachePolicy policy = DiskCachePolicy::kLru) {
    auto c = DiskCache::open(dir_, budget, policy);
    EXPECT_TRUE(c.ok()) << (c.ok() ? "" : c.error().message);
    return c.ok() ? std::move(c).value() : nullptr;
  }

  static std::vector<std::byte> bytes(size_t n, uint8_t seed) {
    std::vector<std::byte> v(n);
    for (size_t i = 0; i < n; ++i) v[i] = std::byte(uint8_t(seed + i * 7));
    return v;
  }

  static std::optional<std::vector<std::byte>> get(DiskCache& c, const std::string& key, size_t n) {
    std::vector<std::byte> out(n);
    std::optional<uint64_t> got = c.read(key, out);
    if (!got) return std::nullopt;
    out.resize(*got);
    return out;
  }

  // The only entry file (tests that damage one insert exactly one).
  fs::path only_entry_file() {
    std::vector<fs::path> files;
    for (const auto& f : fs::directory_iterator(dir_ / "entries")) files.push_back(f.path());
    EXPECT_EQ(files.size(), 1u);
    return files.empty() ? fs::path() : files[0];
  }

  fs::path dir_;
};

TEST_F(DiskCacheTest, EntriesSurviveARestart) {
  const std::string a = DiskCache::key_of("textures/000/00000001.dds", 0, 148);
  const std::string b = DiskCache::key_of("textures/000/00000001.dds", 148, 4096);
  {
    auto c = open();
    c->insert(a, bytes(148, 1));
    c->insert(b, bytes(4096, 2));
    EXPECT_EQ(c->bytes(), 148u + 4096u);
  }
  auto c = open();
  EXPECT_EQ(c->entries(), 2u);
  EXPECT_EQ(c->bytes(), 148u + 4096u);
  EXPECT_EQ(get(*c, a, 148), bytes(148, 1));
  EXPECT_EQ(get(*c, b, 4096), bytes(4096, 2));
  EXPECT_FALSE(get(*c, DiskCache::key_of("textures/000/00000001.dds", 148, 4095), 4096)) << "keys are exact ranges";
}

TEST_F(DiskCacheTest, AFlippedPayloadByteIsDetectedDroppedAndNeverServed) {
  const std::string key = DiskCache::key_of("t.dds", 0, 1000);
  auto c = open();
  c->insert(key, bytes(1000, 3));
  const fs::path file = only_entry_file();
  {
    std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(-10, std::ios::end);
    f.put('\xAA');
  }
  EXPECT_FALSE(get(*c, key, 1000));
  EXPECT_EQ(c->counters().corrupt_dropped.load(), 1u);
  EXPECT_FALSE(c->contains(key));
  EXPECT_FALSE(fs::exists(file));
  c->insert(key, bytes(1000, 3));  // fetched again: served again
  EXPECT_EQ(get(*c, key, 1000), bytes(1000, 3));
}

TEST_F(DiskCacheTest, ATornEntryFileIsDroppedAtRestart) {
  const std::string key = DiskCache::key_of("t.dds", 0, 1000);
  {
    auto c = open();
    c->insert(key, bytes(1000, 4));
  }
  fs::resize_file(only_entry_file(), 500);  // a crash in the middle of writing it
  auto c = open();
  EXPECT_EQ(c->entries(), 0u);
  EXPECT_EQ(c->bytes(), 0u);
  EXPECT_FALSE(get(*c, key, 1000));
}

TEST_F(DiskCacheTest, AnEntryFileReplacedBehindTheCachesBackIsNeverServed) {
  // Same length, other bytes, header intact except the checksum no longer matches.
  const std::string key = DiskCache::key_of("t.dds", 0, 64);
  auto c = open();
  c->insert(key, bytes(64, 5));
  const fs::path file = only_entry_file();
  std::vector<char> all(fs::file_size(file));
  std::ifstream(file, std::ios::binary).read(all.data(), std::streamsize(all.size()));
  for (size_t i = all.size() - 64; i < all.size(); ++i) all[i] = 0;
  std::ofstream(file, std::ios::binary | std::ios::trunc).write(all.data(), std::streamsize(all.size()));
  EXPECT_FALSE(get(*c, key, 64));
}

TEST_F(DiskCacheTest, ATornIndexTailKeepsTheLinesBeforeIt) {
  const std::string a = DiskCache::key_of("a", 0, 10), b = DiskCache::key_of("b", 0, 10);
  {
    auto c = open();
    c->insert(a, bytes(10, 1));
    c->insert(b, bytes(10, 2));
  }
  std::ofstream(dir_ / "index", std::ios::app) << "I 99 10 c@0+10\t0123";  // half a line, no newline
  auto c = open();
  EXPECT_EQ(c->entries(), 2u);
  EXPECT_EQ(get(*c, a, 10), bytes(10, 1));
  EXPECT_EQ(get(*c, b, 10), bytes(10, 2));
}

TEST_F(DiskCacheTest, ACorruptIndexLineEndsTheReplayAndOrphanFilesAreDeleted) {
  const std::string a = DiskCache::key_of("a", 0, 10), b = DiskCache::key_of("b", 0, 10);
  {
    auto c = open();
    c->insert(a, bytes(10, 1));
    c->insert(b, bytes(10, 2));
  }
  // The index is rewritten compactly at close: line 1 is a, line 2 is b. Damage line 2's text.
  std::string text;
  {
    std::ifstream in(dir_ / "index");
    std::stringstream s;
    s << in.rdbuf();
    text = s.str();
  }
  const size_t second = text.find('\n') + 1;
  ASSERT_LT(second, text.size());
  text[second + 2] = text[second + 2] == '9' ? '8' : '9';  // a digit of b's sequence number
  std::ofstream(dir_ / "index", std::ios::trunc) << text;
  auto c = open();
  EXPECT_EQ(c->entries(), 1u);
  EXPECT_TRUE(c->contains(a));
  EXPECT_FALSE(c->contains(b));
  size_t files = 0;
  for (const auto& f : fs::directory_iterator(dir_ / "entries")) files += f.is_regular_file();
  EXPECT_EQ(files, 1u) << "b's file is named by no line: deleted";
}

TEST_F(DiskCacheTest, LruKeepsWhatWasReadFifoEvictsInInsertionOrder) {
  const std::string a = DiskCache::key_of("a", 0, 100), b = DiskCache::key_of("b", 0, 100),
                    c3 = DiskCache::key_of("c", 0, 100), d = DiskCache::key_of("d", 0, 100);
  for (DiskCachePolicy policy : {DiskCachePolicy::kLru, DiskCachePolicy::kFifo}) {
    fs::remove_all(dir_);
    auto c = open(300, policy);
    c->insert(a, bytes(100, 1));
    c->insert(b, bytes(100, 2));
    c->insert(c3, bytes(100, 3));
    ASSERT_TRUE(get(*c, a, 100));
    c->insert(d, bytes(100, 4));
    EXPECT_LE(c->bytes(), 300u);
    if (policy == DiskCachePolicy::kLru) {
      EXPECT_TRUE(c->contains(a));
      EXPECT_FALSE(c->contains(b));
    } else {
      EXPECT_FALSE(c->contains(a));
      EXPECT_TRUE(c->contains(b));
    }
    EXPECT_EQ(c->counters().evictions.load(), 1u);
  }
}

TEST_F(DiskCacheTest, LruOrderSurvivesARestart) {
  const std::string a = DiskCache::key_of("a", 0, 100), b = DiskCache::key_of("b", 0, 100),
                    c3 = DiskCache::key_of("c", 0, 100), d = DiskCache::key_of("d", 0, 100);
  {
    auto c = open(300);
    c->insert(a, bytes(100, 1));
    c->insert(b, bytes(100, 2));
    c->insert(c3, bytes(100, 3));
    ASSERT_TRUE(get(*c, a, 100));
  }
  auto c = open(300);
  c->insert(d, bytes(100, 4));
  EXPECT_TRUE(c->contains(a));
  EXPECT_FALSE(c->contains(b));
}

TEST_F(DiskCacheTest, ASmallerBudgetAtRestartEvictsDownToIt) {
  {
    auto c = open(1000);
    for (int i = 0; i < 10; ++i) c->insert(DiskCache::key_of("k", uint64_t(i), 100), bytes(100, uint8_t(i)));
  }
  auto c = open(450);
  EXPECT_LE(c->bytes(), 450u);
  EXPECT_EQ(c->entries(), 4u);
  EXPECT_TRUE(c->contains(DiskCache::key_of("k", 9, 100))) << "the newest stay";
}

TEST_F(DiskCacheTest, DataLargerThanTheBudgetOrBadKeysAreNotStored) {
  auto c = open(100);
  c->insert("big", bytes(101, 1));
  c->insert("bad\nkey", bytes(10, 1));
  EXPECT_EQ(c->entries(), 0u);
}

TEST_F(DiskCacheTest, ASecondOwnerOfTheFolderIsRefusedNamingIt) {
  auto first = open();
  auto second = DiskCache::open(dir_, 1 << 20, DiskCachePolicy::kLru);
  ASSERT_FALSE(second.ok());
  EXPECT_NE(second.error().message.find(dir_.string()), std::string::npos);
  EXPECT_NE(second.error().message.find(std::to_string(::getpid())), std::string::npos) << second.error().message;
  first.reset();
  EXPECT_TRUE(DiskCache::open(dir_, 1 << 20, DiskCachePolicy::kLru).ok());
}

TEST(DiskCachePolicyName, ParsesLruAndFifoOnly) {
  EXPECT_EQ(*parse_disk_cache_policy("lru"), DiskCachePolicy::kLru);
  EXPECT_EQ(*parse_disk_cache_policy("fifo"), DiskCachePolicy::kFifo);
  auto bad = parse_disk_cache_policy("level");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("storage.disk_cache_policy"), std::string::npos);
}

}  // namespace
}  // namespace texstream::server
