// Cache placement (seed 000 §3.6): one maximum extent per layer, square regions left to right, top to bottom,
// layers in ring order, the oldest layer recycled with its textures evicted.
#include <gtest/gtest.h>

#include "texstream/render/cache/cache_allocator.hpp"

using texstream::TextureId;
using texstream::render::CacheAllocator;

TEST(CacheAllocator, RegionExtentIsNextPowerOfTwoOfTheLargerSide) {
  EXPECT_EQ(CacheAllocator::region_extent(32, 32), 32u);
  EXPECT_EQ(CacheAllocator::region_extent(4, 32), 32u);
  EXPECT_EQ(CacheAllocator::region_extent(64, 8), 64u);
  EXPECT_EQ(CacheAllocator::region_extent(100, 30), 128u);
  EXPECT_EQ(CacheAllocator::region_extent(1, 1), 1u);
}

TEST(CacheAllocator, RegionsFillRowMajorInOneLayerPerExtent) {
  CacheAllocator a(256, 4);
  std::vector<TextureId> evicted;
  // 64-extent layer: 4 x 4 regions. Non-square textures share the square regions of their larger side.
  auto r0 = a.allocate(TextureId(10), 64, 16, evicted);
  auto r1 = a.allocate(TextureId(11), 32, 64, evicted);
  ASSERT_TRUE(r0.ok() && r1.ok());
  EXPECT_EQ(r0->layer, 0u);
  EXPECT_EQ(r1->layer, 0u);
  EXPECT_EQ(r0->origin_x, 0u);
  EXPECT_EQ(r1->origin_x, 64u);
  EXPECT_EQ(r1->origin_y, 0u);
  // A different extent opens the next layer.
  auto r2 = a.allocate(TextureId(12), 128, 128, evicted);
  ASSERT_TRUE(r2.ok());
  EXPECT_EQ(r2->layer, 1u);
  // Fill the 64 layer: region 4 starts the second row.
  for (uint32_t t = 13; t < 15; ++t) ASSERT_TRUE(a.allocate(TextureId(t), 64, 64, evicted).ok());
  auto r5 = a.allocate(TextureId(15), 64, 64, evicted);
  ASSERT_TRUE(r5.ok());
  EXPECT_EQ(r5->index, 4u);
  EXPECT_EQ(r5->origin_x, 0u);
  EXPECT_EQ(r5->origin_y, 64u);
  EXPECT_TRUE(evicted.empty());
  EXPECT_EQ(a.find(TextureId(11))->origin_x, 64u);
}

TEST(CacheAllocator, FullLayerOpensTheNextOneInRingOrder) {
  CacheAllocator a(64, 3);
  std::vector<TextureId> evicted;
  // 32-extent: 4 regions per layer.
  for (uint32_t t = 0; t < 4; ++t) ASSERT_EQ(a.allocate(TextureId(t), 32, 32, evicted)->layer, 0u);
  EXPECT_EQ(a.allocate(TextureId(4), 32, 32, evicted)->layer, 1u);
  EXPECT_EQ(a.allocate(TextureId(5), 64, 64, evicted)->layer, 2u);
  EXPECT_TRUE(evicted.empty());
}

TEST(CacheAllocator, OldestLayerIsRecycledAndItsTexturesEvicted) {
  CacheAllocator a(64, 2);
  std::vector<TextureId> evicted;
  ASSERT_EQ(a.allocate(TextureId(1), 64, 64, evicted)->layer, 0u);  // layer 0 full (one 64 region)
  ASSERT_EQ(a.allocate(TextureId(2), 32, 32, evicted)->layer, 1u);  // layer 1 open for 32
  // Another 64 texture: no free layer, the oldest (0) is recycled.
  auto r = a.allocate(TextureId(3), 64, 64, evicted);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->layer, 0u);
  ASSERT_EQ(evicted.size(), 1u);
  EXPECT_EQ(evicted[0], TextureId(1));
  EXPECT_FALSE(a.find(TextureId(1)).has_value());
  EXPECT_EQ(a.layers_recycled(), 1u);
  // Layer 1 still serves 32-extent textures.
  evicted.clear();
  EXPECT_EQ(a.allocate(TextureId(4), 32, 32, evicted)->layer, 1u);
  EXPECT_TRUE(evicted.empty());
  // Next new layer in ring order is 1 (the oldest now): recycling it evicts both 32-extent textures and it
  // stops being the open 32 layer.
  auto r5 = a.allocate(TextureId(5), 64, 64, evicted);
  ASSERT_TRUE(r5.ok());
  EXPECT_EQ(r5->layer, 1u);
  EXPECT_EQ(evicted.size(), 2u);
  evicted.clear();
  auto r6 = a.allocate(TextureId(6), 32, 32, evicted);  // must open a layer again: recycles 0
  ASSERT_TRUE(r6.ok());
  EXPECT_EQ(r6->layer, 0u);
  ASSERT_EQ(evicted.size(), 1u);
  EXPECT_EQ(evicted[0], TextureId(3));
}

TEST(CacheAllocator, TextureLargerThanALayerIsAnError) {
  CacheAllocator a(64, 2);
  std::vector<TextureId> evicted;
  auto r = a.allocate(TextureId(7), 128, 16, evicted);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("cache.layer_extent_px"), std::string::npos);
}
