#include <gtest/gtest.h>

#include "texstream/server/dispatch/slot_pool.hpp"

namespace texstream::server {
namespace {

TEST(SlotPoolTest, OwnershipFollowsTheRings) {
  SlotPool pool(2);
  EXPECT_EQ(pool.free_count(), 2u);
  const auto a = pool.acquire();
  const auto b = pool.acquire();
  ASSERT_TRUE(a && b);
  EXPECT_EQ(*a, 0u);
  EXPECT_NE(*a, *b);
  EXPECT_FALSE(pool.acquire().has_value());  // exhausted: work waits, not an error
  pool.hand_to_renderer(*a);
  pool.release_unused(*b);
  EXPECT_EQ(pool.owner(*a), SlotPool::Owner::kRenderer);
  EXPECT_EQ(pool.owner(*b), SlotPool::Owner::kServerFree);
  EXPECT_EQ(pool.free_count(), 1u);
  EXPECT_TRUE(pool.release_from_renderer(*a));
  EXPECT_EQ(pool.free_count(), 2u);
}

TEST(SlotPoolTest, UntrustedReleasesAreRefused) {
  SlotPool pool(4);
  EXPECT_FALSE(pool.release_from_renderer(0));  // the server owns it
  EXPECT_FALSE(pool.release_from_renderer(4));  // out of range
  EXPECT_FALSE(pool.release_from_renderer(0xffffffffu));
  const auto s = pool.acquire();
  ASSERT_TRUE(s);
  EXPECT_FALSE(pool.release_from_renderer(*s));  // loading, not the renderer's
  pool.hand_to_renderer(*s);
  EXPECT_TRUE(pool.release_from_renderer(*s));
  EXPECT_FALSE(pool.release_from_renderer(*s));  // a double release
  EXPECT_EQ(pool.free_count(), 4u);
}

}  // namespace
}  // namespace texstream::server
