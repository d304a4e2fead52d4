// Disk cache (issue 4): entries survive a restart through the on-disk index; a corrupt or torn entry is
// dropped and never served; a damaged index line ends the replay there; LRU and FIFO evict in their orders
// (also across a restart); a second owner of the folder is refused; a file system smaller than the budget (a
// 1 MiB tmpfs in a mount namespace of the test's own: root only) keeps taking new entries. Files only: no
// network, shm or clock.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "../support/forked_child.hpp"
#include "test_temp_dir.hpp"
#include "texstream/server/storage/disk_cache.hpp"

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

  // Disk space one entry takes in this test's folder (its file rounded up to the file system's block).
  uint64_t fp(const std::string& key, uint64_t payload) {
    const fs::path probe = dir_.string() + "-probe";
    uint64_t out = 0;
    {
      auto c = DiskCache::open(probe, 1 << 20, DiskCachePolicy::kLru);
      EXPECT_TRUE(c.ok());
      if (c.ok()) out = (*c)->footprint(key, payload);
    }
    fs::remove_all(probe);
    return out;
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
    // What the files take on disk: whole blocks each, so the 148-byte entry counts a block (4 KiB here).
    EXPECT_EQ(c->bytes(), c->footprint(a, 148) + c->footprint(b, 4096));
    EXPECT_GT(c->footprint(a, 148), 148u + a.size());
    EXPECT_EQ(c->footprint(a, 148) % 512, 0u);
    EXPECT_GT(c->footprint(b, 4096), 4096u) << "header and key take a second block";
  }
  auto c = open();
  EXPECT_EQ(c->entries(), 2u);
  EXPECT_EQ(c->bytes(), c->footprint(a, 148) + c->footprint(b, 4096));
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
  const uint64_t one = fp(a, 100);  // every key here has the same length
  for (DiskCachePolicy policy : {DiskCachePolicy::kLru, DiskCachePolicy::kFifo}) {
    fs::remove_all(dir_);
    auto c = open(3 * one, policy);
    c->insert(a, bytes(100, 1));
    c->insert(b, bytes(100, 2));
    c->insert(c3, bytes(100, 3));
    ASSERT_TRUE(get(*c, a, 100));
    c->insert(d, bytes(100, 4));
    EXPECT_LE(c->bytes(), 3 * one);
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
  const uint64_t one = fp(a, 100);
  {
    auto c = open(3 * one);
    c->insert(a, bytes(100, 1));
    c->insert(b, bytes(100, 2));
    c->insert(c3, bytes(100, 3));
    ASSERT_TRUE(get(*c, a, 100));
  }
  auto c = open(3 * one);
  c->insert(d, bytes(100, 4));
  EXPECT_TRUE(c->contains(a));
  EXPECT_FALSE(c->contains(b));
}

TEST_F(DiskCacheTest, ASmallerBudgetAtRestartEvictsDownToIt) {
  const uint64_t one = fp(DiskCache::key_of("k", 0, 100), 100);  // keys k@0..k@9: the same length
  {
    auto c = open(10 * one);
    for (int i = 0; i < 10; ++i) c->insert(DiskCache::key_of("k", uint64_t(i), 100), bytes(100, uint8_t(i)));
    EXPECT_EQ(c->entries(), 10u);
  }
  auto c = open(4 * one + one / 2);
  EXPECT_LE(c->bytes(), 4 * one + one / 2);
  EXPECT_EQ(c->entries(), 4u);
  EXPECT_TRUE(c->contains(DiskCache::key_of("k", 9, 100))) << "the newest stay";
}

TEST_F(DiskCacheTest, DataLargerThanTheBudgetOrBadKeysAreNotStored) {
  const uint64_t one = fp("big", 100);
  auto c = open(one);
  c->insert("big", bytes(one, 1));  // its file takes a block more than the budget
  c->insert("bad\nkey", bytes(10, 1));
  EXPECT_EQ(c->entries(), 0u);
  c->insert("big", bytes(100, 1));
  EXPECT_EQ(c->entries(), 1u) << "one block fits";
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
  const auto parse = [](const std::string& name) {
    return parse_choice<DiskCachePolicy>("storage.disk_cache_policy", name);
  };
  EXPECT_EQ(*parse("lru"), DiskCachePolicy::kLru);
  EXPECT_EQ(*parse("fifo"), DiskCachePolicy::kFifo);
  auto bad = parse("level");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("storage.disk_cache_policy"), std::string::npos);
}

TEST_F(DiskCacheTest, AFileSystemSmallerThanTheBudgetKeepsTakingNewEntries) {
  // Before: a 64 MiB budget on a 1 MiB disk filled the disk, then every later entry failed to write (one
  // warning each: 21570 in a 7 s run) and was never cached. Now the budget is lowered at open to what the disk
  // holds, and again when another writer fills the disk, so the newest entries are always there.
  fs::create_directories(dir_);
  const test::ChildResult r = test::run_in_child([&](const auto& finish) {
    if (!test::mount_private_tmpfs(dir_.string(), "1m")) {
      finish(std::string("no mount namespace here: ") + std::strerror(errno), test::kChildCannotRun);
    }
    const fs::path folder = dir_ / "dc";
    const size_t n = 64 << 10;
    const auto key = [](int i) { return DiskCache::key_of("textures/x.dds", static_cast<uint64_t>(i) * 65536, 65536); };
    const auto holds = [&](DiskCache& c, int i) {
      const auto got = get(c, key(i), n);
      return got && *got == bytes(n, static_cast<uint8_t>(i));
    };
    {
      auto opened = DiskCache::open(folder, 64u << 20, DiskCachePolicy::kLru);
      if (!opened.ok()) finish("open: " + opened.error().message, 1);
      DiskCache& c = **opened;
      if (c.budget() >= (1u << 20)) finish("the budget was not lowered to the disk: " + std::to_string(c.budget()), 1);
      for (int i = 0; i < 40; ++i) c.insert(key(i), bytes(n, static_cast<uint8_t>(i)));
      for (int i = 37; i < 40; ++i) {
        if (!holds(c, i)) finish("entry " + std::to_string(i) + " of 40 is not cached (disk full?)", 1);
      }
      // Another writer takes the rest of the disk.
      {
        std::ofstream filler(dir_ / "filler", std::ios::binary);
        const std::vector<char> block(4096, 'f');
        for (int k = 0; k < 1024 && filler.write(block.data(), block.size()); ++k) filler.flush();
      }
      for (int i = 40; i < 44; ++i) c.insert(key(i), bytes(n, static_cast<uint8_t>(i)));
      if (holds(c, 40)) finish("entry 40 was written into a full disk?", 1);  // the write that found it full
      if (!holds(c, 43)) finish("the newest entry is not cached after another writer filled the disk", 1);
    }
    fs::remove(dir_ / "filler");
    // The index stayed whole through the failed writes: the newest entry survives a restart.
    auto reopened = DiskCache::open(folder, 64u << 20, DiskCachePolicy::kLru);
    if (!reopened.ok()) finish("reopen: " + reopened.error().message, 1);
    if (!holds(**reopened, 43)) finish("the newest entry did not survive a restart", 1);
    finish("", 0);
  });
  ASSERT_EQ(r.signal, 0) << "the child died by signal " << r.signal;
  if (r.code == test::kChildCannotRun) GTEST_SKIP() << r.text;
  EXPECT_EQ(r.code, 0) << r.text;
}

}  // namespace
}  // namespace texstream::server
