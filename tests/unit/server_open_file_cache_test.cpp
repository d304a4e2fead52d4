// OpenFileCache: files checked out and handed back, bounded with LRU closing, duplicates closed.
#include <gtest/gtest.h>

#include "texstream/server/storage/open_file_cache.hpp"

namespace texstream::server {
namespace {

// Counts live instances: a destroyed file is a closed one.
class CountedFile final : public StorageFile {
 public:
  explicit CountedFile(int* live) : live_(live) { ++*live_; }
  ~CountedFile() override { --*live_; }
  Result<uint64_t> read_at(std::span<std::byte>, uint64_t) override { return uint64_t{0}; }
  Result<uint64_t> size() override { return uint64_t{0}; }

 private:
  int* live_;
};

OpenTextureFile make(int* live, const char* name) { return OpenTextureFile{name, std::make_unique<CountedFile>(live)}; }

TEST(OpenFileCache, TakeReturnsWhatWasHandedBackOnce) {
  int live = 0;
  OpenFileCache cache(4);
  EXPECT_FALSE(cache.take(TextureId(7)).has_value());
  cache.give_back(TextureId(7), make(&live, "seven"));
  std::optional<OpenTextureFile> f = cache.take(TextureId(7));
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(f->path, "seven");
  EXPECT_FALSE(cache.take(TextureId(7)).has_value());  // checked out: nobody else gets it
  EXPECT_EQ(live, 1);
}

TEST(OpenFileCache, ClosesTheLeastRecentlyUsedBeyondCapacity) {
  int live = 0;
  OpenFileCache cache(2);
  cache.give_back(TextureId(1), make(&live, "1"));
  cache.give_back(TextureId(2), make(&live, "2"));
  cache.give_back(TextureId(1), *cache.take(TextureId(1)));  // 1 is now the most recent
  cache.give_back(TextureId(3), make(&live, "3"));           // closes 2
  EXPECT_EQ(live, 2);
  EXPECT_EQ(cache.size(), 2u);
  EXPECT_FALSE(cache.take(TextureId(2)).has_value());
  EXPECT_TRUE(cache.take(TextureId(1)).has_value());
  EXPECT_TRUE(cache.take(TextureId(3)).has_value());
  EXPECT_EQ(live, 0);  // the taken files died with their optionals
}

TEST(OpenFileCache, ASecondFileForTheSameTextureIsClosed) {
  int live = 0;
  OpenFileCache cache(4);
  cache.give_back(TextureId(5), make(&live, "first"));
  cache.give_back(TextureId(5), make(&live, "second"));  // two workers opened it at once
  EXPECT_EQ(live, 1);
  EXPECT_EQ(cache.take(TextureId(5))->path, "first");
}

TEST(OpenFileCache, CapacityZeroKeepsNothingOpen) {
  int live = 0;
  OpenFileCache cache(0);
  cache.give_back(TextureId(1), make(&live, "1"));
  EXPECT_EQ(live, 0);
  EXPECT_EQ(cache.size(), 0u);
}

}  // namespace
}  // namespace texstream::server
