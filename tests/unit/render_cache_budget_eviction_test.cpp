// CacheAllocator::evict_oldest (the memory budget's eviction, seed 000 §3.6 ring order) together with layer
// recycling: both always take the oldest live layer.
#include <gtest/gtest.h>

#include <algorithm>

#include "texstream/render/cache/cache_allocator.hpp"

using texstream::TextureId;
using texstream::render::CacheAllocator;

TEST(CacheBudgetEviction, EvictsTheOldestLiveLayerWithItsTextures) {
  CacheAllocator a(64, 4);
  std::vector<TextureId> evicted;
  ASSERT_EQ(a.allocate(TextureId(1), 64, 64, evicted)->layer, 0u);
  ASSERT_EQ(a.allocate(TextureId(2), 32, 32, evicted)->layer, 1u);
  ASSERT_EQ(a.allocate(TextureId(3), 32, 32, evicted)->layer, 1u);
  EXPECT_EQ(a.live_layers(), 2u);
  auto l = a.evict_oldest(evicted);
  ASSERT_TRUE(l.has_value());
  EXPECT_EQ(*l, 0u);
  EXPECT_EQ(evicted, std::vector<TextureId>{TextureId(1)});
  EXPECT_FALSE(a.find(TextureId(1)).has_value());
  evicted.clear();
  EXPECT_EQ(*a.evict_oldest(evicted), 1u);
  std::sort(evicted.begin(), evicted.end());
  EXPECT_EQ(evicted, (std::vector<TextureId>{TextureId(2), TextureId(3)}));
  EXPECT_EQ(a.live_layers(), 0u);
  EXPECT_FALSE(a.evict_oldest(evicted).has_value());
  // The 32 layer was the open one: a new 32 texture opens the next layer in ring order (2), not layer 1.
  evicted.clear();
  EXPECT_EQ(a.allocate(TextureId(4), 32, 32, evicted)->layer, 2u);
  EXPECT_TRUE(evicted.empty());
}

TEST(CacheBudgetEviction, RecyclingAfterBudgetEvictionStillTakesTheOldest) {
  CacheAllocator a(64, 3);
  std::vector<TextureId> evicted;
  for (uint32_t t = 0; t < 3; ++t) ASSERT_EQ(a.allocate(TextureId(t), 64, 64, evicted)->layer, t);
  ASSERT_EQ(*a.evict_oldest(evicted), 0u);  // budget: layer 0 goes
  evicted.clear();
  // Layer 0 is free: the next assignment takes it without evicting anything.
  EXPECT_EQ(a.allocate(TextureId(10), 64, 64, evicted)->layer, 0u);
  EXPECT_TRUE(evicted.empty());
  // Now all three are live again; the oldest is layer 1.
  EXPECT_EQ(a.allocate(TextureId(11), 64, 64, evicted)->layer, 1u);
  EXPECT_EQ(evicted, std::vector<TextureId>{TextureId(1)});
  EXPECT_EQ(a.live_layers(), 3u);
}
