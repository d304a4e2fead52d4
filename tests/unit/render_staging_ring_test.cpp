// Staging ring: allocations in ring order, alignment, wrap-around, and space reused only after release, in
// allocation order.
#include <gtest/gtest.h>

#include "texstream/render/cache/staging_ring.hpp"

using texstream::render::StagingRing;

TEST(StagingRing, AllocatesAlignedAndWraps) {
  StagingRing r(1024);
  auto a = r.allocate(100, 16);
  auto b = r.allocate(100, 16);
  ASSERT_TRUE(a && b);
  EXPECT_EQ(a->offset, 0u);
  EXPECT_EQ(b->offset, 112u);    // 100 rounded up to 16
  auto c = r.allocate(900, 16);  // does not fit in what is left, nor after a wrap while a and b are live
  EXPECT_FALSE(c.has_value());
  r.release(a->id);
  r.release(b->id);
  auto d = r.allocate(900, 16);  // everything released: wraps to 0 (212 + 900 > 1024)
  ASSERT_TRUE(d);
  EXPECT_EQ(d->offset, 0u);
}

TEST(StagingRing, SpaceReturnsInAllocationOrderOnly) {
  StagingRing r(300);
  auto a = r.allocate(100, 4);
  auto b = r.allocate(100, 4);
  auto c = r.allocate(100, 4);
  ASSERT_TRUE(a && b && c);
  EXPECT_FALSE(r.allocate(4, 4).has_value());
  r.release(b->id);  // b is done but a is not: nothing comes back yet
  EXPECT_FALSE(r.allocate(4, 4).has_value());
  r.release(a->id);  // a and b come back together
  auto d = r.allocate(200, 4);
  ASSERT_TRUE(d);
  EXPECT_EQ(d->offset, 0u);
  EXPECT_EQ(r.live(), 2u);
}

TEST(StagingRing, NeverHandsOutOverlappingLiveRanges) {
  StagingRing r(4096);
  std::vector<StagingRing::Allocation> live;
  uint64_t seed = 12345;
  for (int i = 0; i < 2000; ++i) {
    seed = seed * 6364136223846793005ull + 1442695040888963407ull;
    const uint64_t bytes = 1 + (seed >> 33) % 700;
    if (auto a = r.allocate(bytes, 16)) {
      for (const auto& l : live) {
        const bool disjoint = a->offset + a->size <= l.offset || l.offset + l.size <= a->offset;
        ASSERT_TRUE(disjoint) << "allocation " << i;
      }
      EXPECT_EQ(a->offset % 16, 0u);
      EXPECT_LE(a->offset + a->size, 4096u);
      live.push_back(*a);
    } else {
      ASSERT_FALSE(live.empty());
      r.release(live.front().id);  // oldest first, as GPU copies complete
      live.erase(live.begin());
    }
  }
}

TEST(StagingRing, OversizedRequestsAreRefused) {
  StagingRing r(64);
  EXPECT_FALSE(r.allocate(65, 4).has_value());
  EXPECT_FALSE(r.allocate(0, 4).has_value());
  EXPECT_TRUE(r.allocate(64, 4).has_value());
}
