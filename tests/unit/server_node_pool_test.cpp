// NodePool and PoolAllocator (the policies' list nodes), and the policies' insert_new(): nodes the cache
// reaches through its own index, never through the policy's key index.
#include <gtest/gtest.h>

#include <list>
#include <set>
#include <vector>

#include "texstream/server/cache/level_eviction_policy.hpp"
#include "texstream/server/cache/lru_eviction_policy.hpp"
#include "texstream/server/cache/node_pool.hpp"

namespace texstream::server {
namespace {

MipKey key(uint32_t texture, uint32_t mip = 0) { return MipKey(TextureId(texture), MipLevel(mip)); }

TEST(NodePoolTest, ReservedBlocksAreHandedOutWithoutGrowingAndReused) {
  NodePool pool;
  pool.reserve(100);
  EXPECT_EQ(pool.capacity(), 100u);
  std::set<void*> seen;
  std::vector<void*> blocks;
  for (int i = 0; i < 100; ++i) {
    void* p = pool.allocate();
    EXPECT_EQ(reinterpret_cast<uintptr_t>(p) % NodePool::kBlockBytes, 0u);
    EXPECT_TRUE(seen.insert(p).second) << "block handed out twice";
    blocks.push_back(p);
  }
  EXPECT_EQ(pool.capacity(), 100u);  // no growth within the reserve
  EXPECT_EQ(pool.in_use(), 100u);
  pool.deallocate(blocks[42]);
  EXPECT_EQ(pool.allocate(), blocks[42]);  // the freed block first
  pool.reserve(50);                        // less than held: nothing changes
  EXPECT_EQ(pool.capacity(), 100u);
  void* more = pool.allocate();  // beyond the reserve: a new chunk
  EXPECT_EQ(pool.capacity(), 100u + NodePool::kChunkBlocks);
  EXPECT_EQ(seen.count(more), 0u);
  pool.deallocate(more);
  for (void* p : blocks) pool.deallocate(p);
  EXPECT_EQ(pool.in_use(), 0u);
}

TEST(NodePoolTest, AListOnThePoolBehavesAsAList) {
  NodePool pool;
  std::list<int, PoolAllocator<int>> l{PoolAllocator<int>(pool)};
  for (int i = 0; i < 3000; ++i) l.push_back(i);  // past one chunk
  EXPECT_EQ(pool.in_use(), 3000u);
  int expect = 0;
  for (int v : l) EXPECT_EQ(v, expect++);
  l.remove_if([](int v) { return v % 2 == 0; });
  EXPECT_EQ(pool.in_use(), 1500u);
  l.clear();
  EXPECT_EQ(pool.in_use(), 0u);
}

// insert_new() nodes order and evict exactly as on_insert() ones; erase() of one leaves key-tracked entries
// alone, and the key index never sees them.
template <class Policy>
void check_insert_new(Policy& p) {
  p.reserve(16);
  PolicyNode* a = p.insert_new(key(1));
  PolicyNode* b = p.insert_new(key(2));
  p.on_insert(key(3));
  auto all = [](MipKey) { return true; };
  EXPECT_EQ(p.pick_victim(all), key(1));  // least recently used first
  p.touch(a);
  EXPECT_EQ(p.pick_victim(all), key(2));
  p.on_erase(key(2));  // not in the key index: a no-op
  EXPECT_EQ(p.pick_victim(all), key(2));
  p.erase(b);
  EXPECT_EQ(p.pick_victim(all), key(3));
  p.on_erase(key(3));  // key-tracked: gone
  EXPECT_EQ(p.pick_victim(all), key(1));
  p.erase(a);
  EXPECT_FALSE(p.pick_victim(all).has_value());
}

TEST(PolicyInsertNewTest, Lru) {
  LruEvictionPolicy p;
  check_insert_new(p);
}

TEST(PolicyInsertNewTest, LevelWithEqualLevels) {
  LevelEvictionPolicy p([](MipKey) { return 3u; });  // one level: plain LRU order
  check_insert_new(p);
}

}  // namespace
}  // namespace texstream::server
