// The lru cache's placement (QuadtreeAllocator) and the cache image's shape from the device and the budget
// (choose_cache_geometry): docs/design/cache_budget.md.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <map>
#include <random>
#include <vector>

#include "texstream/render/cache/cache_geometry.hpp"
#include "texstream/render/cache/quadtree_allocator.hpp"

using texstream::CacheEviction;
using texstream::TexelFormat;
using texstream::TextureId;
using texstream::render::cache_layer_bytes;
using texstream::render::CacheGeometryInputs;
using texstream::render::CacheRegion;
using texstream::render::choose_cache_geometry;
using texstream::render::QuadtreeAllocator;

namespace {

// Texel-exact occupancy of the regions handed out: every texel of mip 0 belongs to at most one texture.
bool overlaps(const CacheRegion& a, const CacheRegion& b) {
  return a.layer == b.layer && a.origin_x < b.origin_x + b.width && b.origin_x < a.origin_x + a.width &&
         a.origin_y < b.origin_y + b.height && b.origin_y < a.origin_y + a.height;
}

}  // namespace

TEST(QuadtreeAllocator, RectanglesArePowersOfTwoPerSide) {
  EXPECT_EQ(QuadtreeAllocator::rect_of(2048, 1024, 4), std::make_pair(2048u, 1024u));
  EXPECT_EQ(QuadtreeAllocator::rect_of(300, 200, 4), std::make_pair(512u, 256u));
  EXPECT_EQ(QuadtreeAllocator::rect_of(1, 1, 4), std::make_pair(4u, 4u));
  EXPECT_EQ(QuadtreeAllocator::rect_of(1, 1, 1), std::make_pair(1u, 1u));
}

TEST(QuadtreeAllocator, MixedSizesShareOneLayerAndFillItExactly) {
  // One 1024 layer: a 512², then four 256², then 64² until full; every texel used once.
  QuadtreeAllocator a(1024, 1, 4);
  std::vector<CacheRegion> got;
  uint32_t id = 0;
  got.push_back(*a.allocate(TextureId(id++), 512, 512));
  for (int i = 0; i < 4; ++i) got.push_back(*a.allocate(TextureId(id++), 256, 256));
  while (auto r = a.allocate(TextureId(id), 64, 64)) {
    got.push_back(*r);
    ++id;
  }
  EXPECT_EQ(a.used_texels(), 1024u * 1024u);
  EXPECT_EQ(got.size(), 1u + 4u + (1024u * 1024u - 512u * 512u - 4u * 256u * 256u) / (64u * 64u));
  for (size_t i = 0; i < got.size(); ++i)
    for (size_t j = i + 1; j < got.size(); ++j) ASSERT_FALSE(overlaps(got[i], got[j])) << i << " " << j;
  EXPECT_FALSE(a.allocate(TextureId(id), 4, 4).has_value());
}

TEST(QuadtreeAllocator, ANonSquareTextureTakesItsOwnRectangleAndLeavesTheRest) {
  QuadtreeAllocator a(2048, 1, 4);
  const CacheRegion wide = *a.allocate(TextureId(1), 2048, 1024);
  EXPECT_EQ(wide.width, 2048u);
  EXPECT_EQ(wide.height, 1024u);
  EXPECT_EQ(a.used_texels(), 2048u * 1024u);
  // The other half holds two more 1024² textures.
  const CacheRegion b = *a.allocate(TextureId(2), 1024, 1024);
  const CacheRegion c = *a.allocate(TextureId(3), 1000, 900);
  EXPECT_FALSE(overlaps(wide, b));
  EXPECT_FALSE(overlaps(wide, c));
  EXPECT_FALSE(overlaps(b, c));
  EXPECT_FALSE(a.allocate(TextureId(4), 4, 4).has_value());
  // A tall thin one: 16 x 512 takes 16 x 512 of texels.
  QuadtreeAllocator t(512, 1, 4);
  const CacheRegion thin = *t.allocate(TextureId(1), 16, 512);
  EXPECT_EQ(thin.width * thin.height, 16u * 512u);
  EXPECT_EQ(t.used_texels(), 16u * 512u);
  uint32_t n = 0;
  while (t.allocate(TextureId(100 + n), 16, 16)) ++n;
  EXPECT_EQ(n, (512u * 512u - 16u * 512u) / 256u);
}

TEST(QuadtreeAllocator, FreedRegionsMergeBackIntoWholeLayers) {
  QuadtreeAllocator a(1024, 2, 4);
  std::mt19937 rng(7);
  std::map<uint32_t, CacheRegion> live;
  uint32_t next = 0;
  // Random sizes and orders, frees interleaved; regions never overlap; freeing everything restores one free
  // square per layer.
  for (int step = 0; step < 4000; ++step) {
    if (!live.empty() && (rng() % 3 == 0)) {
      auto it = live.begin();
      std::advance(it, static_cast<long>(rng() % live.size()));
      a.free(TextureId(it->first));
      live.erase(it);
      continue;
    }
    const uint32_t w = 1u + rng() % 300, h = 1u + rng() % 300;
    auto r = a.allocate(TextureId(next), w, h);
    if (!r) continue;
    for (const auto& [id, other] : live) ASSERT_FALSE(overlaps(*r, other)) << "step " << step;
    live.emplace(next++, *r);
  }
  uint64_t used = 0;
  for (const auto& [id, r] : live) used += uint64_t{r.width} * r.height;
  EXPECT_EQ(a.used_texels(), used);
  for (const auto& [id, r] : live) a.free(TextureId(id));
  EXPECT_EQ(a.used_texels(), 0u);
  EXPECT_EQ(a.free_squares(), 2u);
  EXPECT_TRUE(a.allocate(TextureId(next), 1024, 1024).has_value());
}

TEST(QuadtreeAllocator, LowestAddressFirstSoNeighboursArePlacedTogether) {
  QuadtreeAllocator a(1024, 2, 4);
  const CacheRegion r0 = *a.allocate(TextureId(0), 64, 64);
  const CacheRegion r1 = *a.allocate(TextureId(1), 64, 64);
  EXPECT_EQ(r0.layer, 0u);
  EXPECT_EQ(r0.origin_x, 0u);
  EXPECT_EQ(r0.origin_y, 0u);
  EXPECT_EQ(r1.origin_x, 64u);
  EXPECT_EQ(r1.origin_y, 0u);
  a.free(TextureId(0));
  EXPECT_EQ(a.allocate(TextureId(2), 64, 64)->origin_x, 0u);  // the hole is reused first
}

TEST(CacheGeometry, LruGetsLargeLayersAndAddressSpaceForManyTimesTheBudget) {
  CacheGeometryInputs in;
  in.format = TexelFormat::kBc1;
  in.memory_bytes = 1ull << 30;
  in.largest_texture = 512;
  in.max_image_dimension = 32768;
  in.max_array_layers = 2048;
  in.sparse_address_space = 1ull << 40;  // NVIDIA
  auto g = choose_cache_geometry(in);
  ASSERT_TRUE(g.ok()) << g.error().message;
  EXPECT_EQ(g->layer_extent, 16384u);
  // Whole layers: within one layer of kAddressPerBudget x the budget.
  EXPECT_GE(g->virtual_bytes, (texstream::render::kAddressPerBudget - 1) * in.memory_bytes);
  EXPECT_LE(g->virtual_bytes, texstream::render::kAddressPerBudget * in.memory_bytes);
  // lavapipe: 2 GiB of address space, RGBA8, 128 MiB budget: what the device has, well above the budget.
  in.format = TexelFormat::kRgba8;
  in.memory_bytes = 128ull << 20;
  in.max_image_dimension = 16384;
  in.sparse_address_space = 2ull << 30;
  g = choose_cache_geometry(in);
  ASSERT_TRUE(g.ok()) << g.error().message;
  EXPECT_GE(g->virtual_bytes, 8 * in.memory_bytes);
  EXPECT_LE(g->virtual_bytes, in.sparse_address_space);
  EXPECT_GE(g->layer_extent, 512u);
}

TEST(CacheGeometry, TheBudgetNeverOutgrowsTheAddressSpaceSilently) {
  // A budget above what the device can address: the image takes what it can (the address space is then the
  // limit, and addressable_vs_budget in cache.json shows it); it never exceeds the device.
  CacheGeometryInputs in;
  in.format = TexelFormat::kRgba8;
  in.memory_bytes = 8ull << 30;
  in.largest_texture = 2048;
  in.max_image_dimension = 16384;
  in.max_array_layers = 2048;
  in.sparse_address_space = 2ull << 30;
  auto g = choose_cache_geometry(in);
  ASSERT_TRUE(g.ok()) << g.error().message;
  EXPECT_LE(g->virtual_bytes, in.sparse_address_space);
  EXPECT_GE(g->layer_extent, 2048u);
}

TEST(CacheGeometry, RingLayersAreTheLargestTextureAndTexturesBeyondTheDeviceAreRefused) {
  CacheGeometryInputs in;
  in.eviction = CacheEviction::kRing;
  in.format = TexelFormat::kBc1;
  in.memory_bytes = 1ull << 30;
  in.largest_texture = 300;
  in.max_image_dimension = 16384;
  in.max_array_layers = 2048;
  in.sparse_address_space = 1ull << 40;
  auto g = choose_cache_geometry(in);
  ASSERT_TRUE(g.ok());
  EXPECT_EQ(g->layer_extent, 512u);
  EXPECT_EQ(g->layers, 2048u);  // as many as the device allows: the seed's answer to thrash
  EXPECT_EQ(g->virtual_bytes, 2048 * cache_layer_bytes(TexelFormat::kBc1, 512));
  in.largest_texture = 40000;
  auto too_large = choose_cache_geometry(in);
  ASSERT_FALSE(too_large.ok());
  EXPECT_NE(too_large.error().message.find("cache.layer_extent_px"), std::string::npos);
  // Set by the user: kept.
  in.largest_texture = 300;
  in.layer_extent = 1024;
  in.layers = 7;
  g = choose_cache_geometry(in);
  ASSERT_TRUE(g.ok());
  EXPECT_EQ(g->layer_extent, 1024u);
  EXPECT_EQ(g->layers, 7u);
}
