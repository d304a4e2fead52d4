#include <gtest/gtest.h>

#include <vector>

#include "texstream/server/dispatch/request_scheduler.hpp"

namespace texstream::server {
namespace {

LoadRequest req(uint32_t texture, uint32_t mip, uint64_t generation, float priority) {
  return LoadRequest{TextureId(texture), MipLevel(mip), Generation(generation), priority};
}

LoadRequest page(uint32_t file, pages::PageId p, uint64_t generation, float priority) {
  LoadRequest r{TextureId(file), MipLevel(p.level), Generation(generation), priority};
  r.page = true;
  r.x = p.x;
  r.y = p.y;
  return r;
}

// Pages (kLoadPage) share the mips' heap: one priority order, their own coalescing and supersede, and no key of
// a page is a mip's (texture 0 mip 0 and page file 0's root are different loads).
TEST(RequestSchedulerTest, PagesShareTheHeapWithMipsUnderKeysOfTheirOwn) {
  RequestScheduler s;
  EXPECT_FALSE(s.add(req(0, 0, 1, 2)));
  EXPECT_FALSE(s.add(page(0, {0, 0, 0}, 1, 5)));
  EXPECT_FALSE(s.add(page(0, {1, 1, 0}, 1, 3)));
  EXPECT_FALSE(s.add(page(0, {1, 0, 1}, 1, 1)));
  EXPECT_FALSE(s.add(req(0, 1, 1, 4)));
  EXPECT_EQ(s.size(), 5u);
  EXPECT_TRUE(s.contains(MipKey(TextureId(0), MipLevel(0))));
  EXPECT_NE(page_key(0, {0, 0, 0}), MipKey(TextureId(0), MipLevel(0)));
  EXPECT_NE(page_key(0, {1, 1, 0}), page_key(0, {1, 0, 1}));
  EXPECT_NE(page_key(0, {1, 0, 0}), page_key(1, {1, 0, 0}));
  // A page asked again coalesces like a mip: the older request is the one answered kCancelled.
  const auto cancelled = s.add(page(0, {1, 1, 0}, 2, 6));
  ASSERT_TRUE(cancelled);
  EXPECT_TRUE(cancelled->page);
  EXPECT_EQ(cancelled->generation.value, 1u);
  EXPECT_EQ(cancelled->x, 1u);
  // Generation 2 asked only for that page: everything else of generation 1 is stale, pages and mips alike.
  std::vector<LoadRequest> stale;
  s.supersede_older_than(Generation(2), stale);
  EXPECT_EQ(stale.size(), 4u);
  const auto top = s.pop();
  ASSERT_TRUE(top);
  EXPECT_TRUE(top->page);
  EXPECT_EQ(top->page_id(), (pages::PageId{1, 1, 0}));
  EXPECT_FLOAT_EQ(top->priority, 6);
  EXPECT_TRUE(s.empty());
}

TEST(RequestSchedulerTest, PopsHighestPriorityFirstAndFifoOnTies) {
  RequestScheduler s;
  EXPECT_FALSE(s.add(req(1, 0, 1, 5)));
  EXPECT_FALSE(s.add(req(2, 0, 1, 9)));
  EXPECT_FALSE(s.add(req(3, 0, 1, 5)));
  EXPECT_FALSE(s.add(req(4, 0, 1, 1)));
  EXPECT_EQ(s.size(), 4u);
  EXPECT_EQ(s.top()->texture.value, 2u);
  std::vector<uint32_t> order;
  while (auto r = s.pop()) order.push_back(r->texture.value);
  EXPECT_EQ(order, (std::vector<uint32_t>{2, 1, 3, 4}));
  EXPECT_TRUE(s.empty());
}

TEST(RequestSchedulerTest, DuplicateCoalescesKeepingMaxPriorityAndNewestGeneration) {
  RequestScheduler s;
  ASSERT_FALSE(s.add(req(1, 2, 1, 3)));
  ASSERT_FALSE(s.add(req(7, 0, 1, 5)));
  const auto cancelled = s.add(req(1, 2, 2, 8));
  ASSERT_TRUE(cancelled);
  EXPECT_EQ(cancelled->generation.value, 1u);  // the superseded request is the one answered
  EXPECT_EQ(s.size(), 2u);
  const auto top = s.pop();
  EXPECT_EQ(top->texture.value, 1u);
  EXPECT_EQ(top->generation.value, 2u);
  EXPECT_FLOAT_EQ(top->priority, 8);
  EXPECT_EQ(s.pop()->texture.value, 7u);
  EXPECT_FALSE(s.pop());
}

TEST(RequestSchedulerTest, DuplicateWithLowerPriorityKeepsTheHigherOne) {
  RequestScheduler s;
  ASSERT_FALSE(s.add(req(1, 0, 1, 9)));
  ASSERT_FALSE(s.add(req(2, 0, 1, 5)));
  ASSERT_TRUE(s.add(req(1, 0, 2, 1)));
  EXPECT_EQ(s.pop()->texture.value, 1u);
}

TEST(RequestSchedulerTest, NewerGenerationSupersedesWhatWasNotAskedAgain) {
  RequestScheduler s;
  for (uint32_t t = 0; t < 5; ++t) ASSERT_FALSE(s.add(req(t, 0, 1, static_cast<float>(t))));
  ASSERT_TRUE(s.add(req(3, 0, 2, 1)));   // re-asked in cycle 2
  ASSERT_FALSE(s.add(req(9, 0, 2, 1)));  // new in cycle 2
  std::vector<LoadRequest> cancelled;
  s.supersede_older_than(s.newest_generation(), cancelled);
  EXPECT_EQ(cancelled.size(), 4u);  // 0, 1, 2, 4
  for (const LoadRequest& c : cancelled) {
    EXPECT_EQ(c.generation.value, 1u);
    EXPECT_NE(c.texture.value, 3u);
  }
  EXPECT_EQ(s.size(), 2u);
  std::vector<uint32_t> left;
  while (auto r = s.pop()) {
    EXPECT_EQ(r->generation.value, 2u);
    left.push_back(r->texture.value);
  }
  EXPECT_EQ(left, (std::vector<uint32_t>{3, 9}));  // equal priority: 3 arrived first (cycle 1)
}

TEST(RequestSchedulerTest, RequestOlderThanNewestIsStaleOnArrival) {
  RequestScheduler s;
  ASSERT_FALSE(s.add(req(1, 0, 5, 1)));
  const auto stale = s.add(req(2, 0, 4, 100));
  ASSERT_TRUE(stale);
  EXPECT_EQ(stale->texture.value, 2u);
  EXPECT_EQ(s.size(), 1u);
}

TEST(RequestSchedulerTest, ManyPriorityRaisesKeepTheHeapBoundedAndCorrect) {
  RequestScheduler s;
  for (uint32_t t = 0; t < 10; ++t) ASSERT_FALSE(s.add(req(t, 0, 1, 0)));
  // Raise texture 4 a thousand times: stale heap nodes pile up and must be compacted away.
  for (int i = 1; i <= 1000; ++i) ASSERT_TRUE(s.add(req(4, 0, 1, static_cast<float>(i))));
  EXPECT_EQ(s.size(), 10u);
  EXPECT_EQ(s.pop()->texture.value, 4u);
  int n = 0;
  while (auto r = s.pop()) {
    EXPECT_NE(r->texture.value, 4u);
    ++n;
  }
  EXPECT_EQ(n, 9);
}

TEST(RequestSchedulerTest, AMipAskedAgainAfterBeingSupersededTakesItsNewPriority) {
  RequestScheduler s;
  ASSERT_FALSE(s.add(req(1, 0, 1, 9)));  // leaves a heap node at priority 9
  std::vector<LoadRequest> cancelled;
  ASSERT_FALSE(s.add(req(2, 0, 2, 5)));
  s.supersede_older_than(Generation(2), cancelled);  // removes (1, 0); its node stays in the heap
  ASSERT_EQ(cancelled.size(), 1u);
  ASSERT_FALSE(s.add(req(1, 0, 2, 1)));   // asked again, now the least urgent
  EXPECT_EQ(s.pop()->texture.value, 2u);  // not (1, 0) at its old priority 9
  EXPECT_EQ(s.pop()->texture.value, 1u);
  EXPECT_TRUE(s.empty());
  EXPECT_FALSE(s.pop());
}

TEST(RequestSchedulerTest, SupersedingTwiceForTheSameGenerationCancelsNothingNew) {
  RequestScheduler s;
  ASSERT_FALSE(s.add(req(1, 0, 1, 1)));
  ASSERT_FALSE(s.add(req(2, 0, 2, 1)));
  std::vector<LoadRequest> cancelled;
  s.supersede_older_than(Generation(2), cancelled);
  EXPECT_EQ(cancelled.size(), 1u);
  ASSERT_FALSE(s.add(req(3, 0, 2, 1)));
  s.supersede_older_than(Generation(2), cancelled);
  EXPECT_EQ(cancelled.size(), 1u);
  EXPECT_EQ(s.size(), 2u);
  ASSERT_FALSE(s.add(req(4, 0, 3, 1)));
  s.supersede_older_than(Generation(3), cancelled);  // a newer generation scans again
  EXPECT_EQ(cancelled.size(), 3u);
  EXPECT_EQ(s.size(), 1u);
}

}  // namespace
}  // namespace texstream::server
