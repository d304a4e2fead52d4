#include <gtest/gtest.h>

#include <memory>
#include <vector>

#include "texstream/server/lru_eviction_policy.hpp"
#include "texstream/server/mip_cache.hpp"

namespace texstream::server {
namespace {

std::shared_ptr<const CachedMip> mip_of(size_t bytes, uint8_t fill) {
  auto m = std::make_shared<CachedMip>();
  m->bytes.assign(bytes, std::byte{fill});
  m->checksum = fill;
  return m;
}

MipKey key(uint32_t texture, uint32_t mip = 0) { return MipKey(TextureId(texture), MipLevel(mip)); }

MipCache make_cache(uint64_t budget) { return MipCache(budget, std::make_unique<LruEvictionPolicy>()); }

TEST(MipCacheTest, LookupHitsAndMissesAreCounted) {
  MipCache cache = make_cache(1000);
  EXPECT_EQ(cache.lookup(key(1)), nullptr);
  ASSERT_TRUE(cache.insert(key(1), mip_of(100, 7)));
  auto hit = cache.lookup(key(1));
  ASSERT_NE(hit, nullptr);
  EXPECT_EQ(hit->bytes.size(), 100u);
  EXPECT_EQ(hit->checksum, 7u);
  EXPECT_FALSE(cache.contains(key(1, 1)));  // another mip of the same texture is another entry
  const MipCacheStats s = cache.stats();
  EXPECT_EQ(s.hits, 1u);
  EXPECT_EQ(s.misses, 1u);
  EXPECT_EQ(s.insertions, 1u);
  EXPECT_EQ(s.bytes, 100u);
  EXPECT_EQ(s.entries, 1u);
}

TEST(MipCacheTest, EvictsLeastRecentlyUsedAndNeverExceedsBudget) {
  MipCache cache = make_cache(300);
  ASSERT_TRUE(cache.insert(key(1), mip_of(100, 1)));
  ASSERT_TRUE(cache.insert(key(2), mip_of(100, 2)));
  ASSERT_TRUE(cache.insert(key(3), mip_of(100, 3)));
  ASSERT_NE(cache.lookup(key(1)), nullptr);  // 1 is now the most recent; 2 is the coldest
  ASSERT_TRUE(cache.insert(key(4), mip_of(100, 4)));
  EXPECT_TRUE(cache.contains(key(1)));
  EXPECT_FALSE(cache.contains(key(2)));
  EXPECT_TRUE(cache.contains(key(3)));
  EXPECT_TRUE(cache.contains(key(4)));
  // A big one pushes out as many cold ones as needed.
  ASSERT_TRUE(cache.insert(key(5), mip_of(250, 5)));
  const MipCacheStats s = cache.stats();
  EXPECT_LE(s.bytes, 300u);
  EXPECT_EQ(s.bytes, 250u);
  EXPECT_EQ(s.evictions, 4u);
  EXPECT_TRUE(cache.contains(key(5)));
}

TEST(MipCacheTest, BudgetHoldsUnderManyRandomInsertions) {
  MipCache cache = make_cache(4096);
  uint64_t x = 12345;
  for (int i = 0; i < 2000; ++i) {
    x = x * 6364136223846793005ull + 1442695040888963407ull;
    const size_t size = 1 + (x >> 33) % 1500;
    (void)cache.insert(key(static_cast<uint32_t>(i)), mip_of(size, 1));
    ASSERT_LE(cache.stats().bytes, 4096u) << "after insertion " << i;
  }
  const MipCacheStats s = cache.stats();
  EXPECT_EQ(s.insertions - s.evictions, s.entries);
}

TEST(MipCacheTest, PinnedEntriesAreNotEvicted) {
  MipCache cache = make_cache(200);
  ASSERT_TRUE(cache.insert(key(1), mip_of(100, 1)));
  ASSERT_TRUE(cache.insert(key(2), mip_of(100, 2)));
  const auto pin = cache.lookup(key(1));  // 1 is pinned (and most recent); 2 is the LRU victim
  ASSERT_TRUE(cache.insert(key(3), mip_of(100, 3)));
  EXPECT_TRUE(cache.contains(key(1)));
  EXPECT_FALSE(cache.contains(key(2)));
  // Now touch 3 so that the pinned 1 is the coldest: the cache must skip it and evict 3.
  ASSERT_NE(cache.lookup(key(3)), nullptr);
  ASSERT_TRUE(cache.insert(key(4), mip_of(100, 4)));
  EXPECT_TRUE(cache.contains(key(1)));
  EXPECT_FALSE(cache.contains(key(3)));
  EXPECT_EQ(pin->bytes.front(), std::byte{1});  // the pinned payload is intact
}

TEST(MipCacheTest, RefusesWhenOnlyPinnedEntriesCouldMakeRoom) {
  MipCache cache = make_cache(200);
  ASSERT_TRUE(cache.insert(key(1), mip_of(100, 1)));
  ASSERT_TRUE(cache.insert(key(2), mip_of(100, 2)));
  const auto pin1 = cache.lookup(key(1));
  const auto pin2 = cache.lookup(key(2));
  EXPECT_FALSE(cache.insert(key(3), mip_of(50, 3)));
  MipCacheStats s = cache.stats();
  EXPECT_EQ(s.rejections, 1u);
  EXPECT_EQ(s.bytes, 200u);
  EXPECT_EQ(s.evictions, 0u);
}

TEST(MipCacheTest, RejectsMipsLargerThanTheBudgetAndZeroBudgetCachesNothing) {
  MipCache cache = make_cache(100);
  EXPECT_FALSE(cache.admissible(101));
  EXPECT_FALSE(cache.insert(key(1), mip_of(101, 1)));
  EXPECT_EQ(cache.stats().rejections, 1u);
  MipCache none = make_cache(0);
  EXPECT_FALSE(none.admissible(1));
  EXPECT_FALSE(none.insert(key(1), mip_of(1, 1)));
  EXPECT_EQ(none.stats().bytes, 0u);
}

TEST(MipCacheTest, ReinsertingAKeyKeepsOneEntry) {
  MipCache cache = make_cache(1000);
  ASSERT_TRUE(cache.insert(key(1), mip_of(100, 1)));
  ASSERT_TRUE(cache.insert(key(1), mip_of(100, 9)));
  const MipCacheStats s = cache.stats();
  EXPECT_EQ(s.entries, 1u);
  EXPECT_EQ(s.bytes, 100u);
  EXPECT_EQ(cache.lookup(key(1))->checksum, 1u);
}

}  // namespace
}  // namespace texstream::server
