#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <map>
#include <random>
#include <vector>

#include "texstream/server/cache/cache_arena.hpp"

namespace texstream::server {
namespace {

constexpr uint64_t kPage = CacheArena::kMinBlock;

TEST(CacheArenaTest, BlocksAreRoundedToPowersOfTwoAndAligned) {
  CacheArena arena(64 * kPage, ArenaPrefault::kNone);
  EXPECT_EQ(arena.capacity(), 64 * kPage);
  EXPECT_EQ(CacheArena::block_bytes(1), kPage);
  EXPECT_EQ(CacheArena::block_bytes(kPage + 1), 2 * kPage);
  std::byte* a = arena.allocate(3 * kPage);  // 4 pages
  ASSERT_NE(a, nullptr);
  EXPECT_TRUE(arena.owns(a));
  EXPECT_EQ(arena.bytes_in_use(), 4 * kPage);
  std::byte* b = arena.allocate(kPage);
  ASSERT_NE(b, nullptr);
  EXPECT_TRUE(b >= a + 4 * kPage || b + kPage <= a);  // no overlap
  arena.free(a, 3 * kPage);
  arena.free(b, kPage);
  EXPECT_EQ(arena.bytes_in_use(), 0u);
}

TEST(CacheArenaTest, FreedBuddiesMergeBackIntoTheWholeArena) {
  CacheArena arena(16 * kPage, ArenaPrefault::kNone);
  std::vector<std::byte*> pages;
  for (int i = 0; i < 16; ++i) {
    std::byte* p = arena.allocate(kPage);
    ASSERT_NE(p, nullptr) << i;
    pages.push_back(p);
  }
  EXPECT_EQ(arena.allocate(kPage), nullptr);  // full
  // Free in a scattered order; only when all are back is one 16-page block available again.
  std::mt19937 rng(3);
  std::shuffle(pages.begin(), pages.end(), rng);
  for (size_t i = 0; i < pages.size(); ++i) {
    EXPECT_EQ(arena.allocate(16 * kPage), nullptr) << "a whole-arena block with " << 16 - i << " pages in use";
    arena.free(pages[i], kPage);
  }
  std::byte* all = arena.allocate(16 * kPage);
  ASSERT_NE(all, nullptr);
  arena.free(all, 16 * kPage);
}

TEST(CacheArenaTest, CapacitiesThatAreNotPowersOfTwoAreUsedWhole) {
  CacheArena arena(13 * kPage + 100, ArenaPrefault::kNow);  // 8 + 4 + 1 pages; the 100 bytes are dropped
  EXPECT_EQ(arena.capacity(), 13 * kPage);
  EXPECT_EQ(arena.largest_block(), 8 * kPage);
  EXPECT_EQ(arena.bytes_warm(), 13 * kPage);
  EXPECT_EQ(arena.allocate(16 * kPage), nullptr);
  std::byte* a = arena.allocate(8 * kPage);
  std::byte* b = arena.allocate(4 * kPage);
  std::byte* c = arena.allocate(kPage);
  ASSERT_NE(a, nullptr);
  ASSERT_NE(b, nullptr);
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(arena.allocate(kPage), nullptr);
  std::memset(c, 7, kPage);  // the last page is inside the mapping
  arena.free(b, 4 * kPage);
  arena.free(c, kPage);
  arena.free(a, 8 * kPage);
  EXPECT_EQ(arena.bytes_in_use(), 0u);
  EXPECT_EQ(arena.allocate(13 * kPage), nullptr);  // 13 pages round to 16: never one block
  std::byte* again = arena.allocate(8 * kPage);
  EXPECT_NE(again, nullptr);
  arena.free(again, 8 * kPage);
}

TEST(CacheArenaTest, RandomAllocationsNeverOverlapAndAccountingHolds) {
  CacheArena arena(256 * kPage, ArenaPrefault::kNone);
  std::mt19937_64 rng(11);
  std::map<std::byte*, uint64_t> live;  // block -> requested bytes
  for (int step = 0; step < 20000; ++step) {
    if (!live.empty() && (rng() % 2 == 0)) {
      auto it = live.begin();
      std::advance(it, static_cast<long>(rng() % live.size()));
      arena.free(it->first, it->second);
      live.erase(it);
    } else {
      const uint64_t bytes = 1 + rng() % (20 * kPage);
      std::byte* p = arena.allocate(bytes);
      if (p == nullptr) continue;
      ASSERT_TRUE(arena.owns(p));
      ASSERT_TRUE(arena.owns(p + CacheArena::block_bytes(bytes) - 1));
      auto next = live.lower_bound(p);
      if (next != live.end()) {
        ASSERT_LE(p + CacheArena::block_bytes(bytes), next->first) << "overlaps the next";
      }
      if (next != live.begin()) {
        auto prev = std::prev(next);
        ASSERT_LE(prev->first + CacheArena::block_bytes(prev->second), p) << "overlaps the previous";
      }
      live.emplace(p, bytes);
    }
    uint64_t in_use = 0;
    for (const auto& [p, b] : live) in_use += CacheArena::block_bytes(b);
    ASSERT_EQ(arena.bytes_in_use(), in_use);
  }
  for (const auto& [p, b] : live) arena.free(p, b);
  EXPECT_EQ(arena.bytes_in_use(), 0u);
  EXPECT_NE(arena.allocate(256 * kPage), nullptr);  // everything merged back
}

TEST(CacheArenaTest, TinyCapacityIsAnEmptyArena) {
  CacheArena arena(kPage - 1, ArenaPrefault::kBackground);
  EXPECT_EQ(arena.capacity(), 0u);
  EXPECT_EQ(arena.allocate(1), nullptr);
  arena.wait_warm();
}

TEST(CacheArenaTest, BackgroundPrefaultWarmsTheWholeArena) {
  CacheArena arena(64 * kPage, ArenaPrefault::kBackground);
  arena.wait_warm();
  EXPECT_EQ(arena.bytes_warm(), 64 * kPage);
}

}  // namespace
}  // namespace texstream::server
