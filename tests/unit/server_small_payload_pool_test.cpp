// SmallPayloadPool: size classes, reuse of freed payloads, its bound, the allocator for shared_ptr control
// blocks, and the cache's use of it (small payloads from the pool, back to it when evicted).
#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <set>
#include <vector>

#include "texstream/server/cache/lru_eviction_policy.hpp"
#include "texstream/server/cache/mip_cache.hpp"
#include "texstream/server/cache/small_payload_pool.hpp"

namespace texstream::server {
namespace {

constexpr uint64_t kSlab = SmallPayloadPool::kSlabBytes;

TEST(SmallPayloadPoolTest, ServesOnlySizesBelowAnArenaBlock) {
  EXPECT_FALSE(SmallPayloadPool::serves(0));
  EXPECT_TRUE(SmallPayloadPool::serves(1));
  EXPECT_TRUE(SmallPayloadPool::serves(CacheArena::kMinBlock - 1));
  EXPECT_FALSE(SmallPayloadPool::serves(CacheArena::kMinBlock));
}

TEST(SmallPayloadPoolTest, SizesRoundUpToTheirClassAndFreedPayloadsAreReused) {
  SmallPayloadPool pool(4 * kSlab);
  ASSERT_EQ(pool.capacity(), 4 * kSlab);
  std::byte* a = pool.allocate(4);   // 1x1 RGBA8: the 16-byte class
  std::byte* b = pool.allocate(16);  // 2x2 RGBA8: the same class, the next block
  ASSERT_NE(a, nullptr);
  ASSERT_NE(b, nullptr);
  EXPECT_TRUE(pool.owns(a));
  EXPECT_EQ(b - a, 16);
  EXPECT_EQ(pool.bytes_in_use(), 32u);
  EXPECT_EQ(pool.slab_bytes(), kSlab);  // one slab for the class so far
  std::byte* c = pool.allocate(1000);   // the 1 KiB class: a slab of its own
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(pool.slab_bytes(), 2 * kSlab);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(c) % 1024, 0u);  // aligned to its class
  // Writing a whole payload touches nothing else: the neighbours keep their bytes.
  std::memset(a, 0xaa, 16);
  std::memset(b, 0xbb, 16);
  std::memset(c, 0xcc, 1000);
  EXPECT_EQ(a[15], std::byte{0xaa});
  EXPECT_EQ(b[0], std::byte{0xbb});
  pool.free(a, 4);
  EXPECT_EQ(pool.bytes_in_use(), 16u + 1024u);
  EXPECT_EQ(pool.allocate(9), a);  // the freed block comes back first
  pool.free(a, 9);
  pool.free(b, 16);
  pool.free(c, 1000);
  EXPECT_EQ(pool.bytes_in_use(), 0u);
  EXPECT_EQ(pool.slab_bytes(), 2 * kSlab);  // slabs stay with their class
}

TEST(SmallPayloadPoolTest, ExhaustionReturnsNullAndFreeingMakesRoomAgain) {
  SmallPayloadPool pool(kSlab);  // exactly one slab
  constexpr uint64_t kSize = 2048;
  std::vector<std::byte*> got;
  std::set<std::byte*> distinct;
  for (;;) {
    std::byte* p = pool.allocate(kSize);
    if (p == nullptr) break;
    got.push_back(p);
    distinct.insert(p);
    ASSERT_LE(got.size(), kSlab / kSize) << "more blocks than the slab holds";
  }
  EXPECT_EQ(got.size(), kSlab / kSize);
  EXPECT_EQ(distinct.size(), got.size());
  EXPECT_EQ(pool.allocate(16), nullptr);  // another class needs a slab: none left
  pool.free(got.back(), kSize);
  EXPECT_EQ(pool.allocate(kSize), got.back());
  for (std::byte* p : got) pool.free(p, kSize);
  EXPECT_EQ(pool.bytes_in_use(), 0u);
}

TEST(SmallPayloadPoolTest, LessThanASlabIsAnEmptyPool) {
  SmallPayloadPool pool(kSlab - 1);
  EXPECT_EQ(pool.capacity(), 0u);
  EXPECT_EQ(pool.allocate(16), nullptr);
}

TEST(SmallPayloadPoolTest, PayloadBytesGoBackToThePoolWithTheirLastOwner) {
  auto pool = std::make_shared<SmallPayloadPool>(kSlab);
  {
    PayloadBytes p(pool, pool->allocate(256), 256);
    EXPECT_TRUE(p.in_pool());
    EXPECT_FALSE(p.in_arena());
    EXPECT_EQ(p.size(), 256u);
    PayloadBytes moved(std::move(p));
    EXPECT_EQ(pool->bytes_in_use(), 256u);
    EXPECT_TRUE(moved.in_pool());
  }
  EXPECT_EQ(pool->bytes_in_use(), 0u);
}

TEST(SmallPayloadPoolTest, TheAllocatorUsesThePoolUntilItIsFullThenTheHeap) {
  auto pool = std::make_shared<SmallPayloadPool>(kSlab);
  std::weak_ptr<SmallPayloadPool> weak = pool;
  std::vector<std::shared_ptr<CachedMip>> mips;
  // 64 KiB of the control blocks' class, then heap ones: both kinds must work and free correctly.
  for (int i = 0; i < 2000; ++i) mips.push_back(std::allocate_shared<CachedMip>(SmallPoolAllocator<CachedMip>(pool)));
  EXPECT_GT(pool->bytes_in_use(), 0u);
  EXPECT_LE(pool->bytes_in_use(), kSlab);
  pool.reset();  // the control blocks keep the pool alive
  EXPECT_FALSE(weak.expired());
  mips.clear();
  EXPECT_TRUE(weak.expired());  // and let it go with the last one
}

TEST(SmallPayloadPoolTest, TheCacheTakesSmallPayloadsFromThePoolAndGetsThemBackOnEviction) {
  // 1 MiB budget: the pool may hold 1/8 of it, two slabs.
  MipCache cache(1 << 20, std::make_unique<LruEvictionPolicy>(), MipCacheOptions{true, ArenaPrefault::kNone});
  auto small = cache.make_payload(64);
  ASSERT_NE(small, nullptr);
  EXPECT_TRUE(small->bytes.in_pool());
  EXPECT_EQ(small->bytes.size(), 64u);
  auto big = cache.make_payload(8 << 10);
  ASSERT_NE(big, nullptr);
  EXPECT_TRUE(big->bytes.in_arena());  // not the pool's: 4 KiB and more come from the arena
  EXPECT_FALSE(big->bytes.in_pool());
  big.reset();
  EXPECT_GE(cache.stats().small_pool_bytes, kSlab);
  std::memset(small->bytes.data(), 7, 64);
  const std::byte* small_block = small->bytes.data();
  ASSERT_TRUE(cache.insert(MipKey(TextureId(1), MipLevel(5)), std::move(small)));
  // The budget counts the small payload's own bytes.
  EXPECT_EQ(cache.stats().bytes, 64u);
  std::vector<std::byte> out(64);
  const std::optional<CachedCopy> c = cache.copy_into(MipKey(TextureId(1), MipLevel(5)), out);
  ASSERT_TRUE(c.has_value());
  EXPECT_EQ(out[63], std::byte{7});
  // Fill the budget with big entries: the small one is evicted (least recently used) and its block goes back
  // to the pool, where the next payload of its class finds it.
  for (uint32_t t = 2; t < 2 + (1 << 20) / (8 << 10) + 1; ++t) {
    auto m = cache.make_payload(8 << 10);
    ASSERT_NE(m, nullptr);
    ASSERT_TRUE(cache.insert(MipKey(TextureId(t), MipLevel(0)), std::move(m)));
    ASSERT_LE(cache.stats().bytes, cache.stats().budget_bytes);
  }
  EXPECT_FALSE(cache.contains(MipKey(TextureId(1), MipLevel(5))));
  auto again = cache.make_payload(64);
  ASSERT_NE(again, nullptr);
  EXPECT_TRUE(again->bytes.in_pool());
  EXPECT_EQ(again->bytes.data(), small_block);
}

TEST(SmallPayloadPoolTest, TheArenasPrefaultWarmsThePoolAfterTheArenaAndPayloadsTakenMeanwhileKeepTheirBytes) {
  // 64 MiB budget: a pool of 8 MiB, beyond the kWarmBytes the pool faults in itself and below kPrefaultBytes.
  constexpr uint64_t kBudget = 64ull << 20;
  static_assert(kBudget / 8 <= SmallPayloadPool::kPrefaultBytes);
  {
    MipCache cold(kBudget, std::make_unique<LruEvictionPolicy>(), MipCacheOptions{true, ArenaPrefault::kNone});
    EXPECT_EQ(cold.stats().small_pool_capacity, kBudget / 8);
    EXPECT_EQ(cold.stats().small_pool_warm_bytes, SmallPayloadPool::kWarmBytes);  // nobody warms the rest
  }
  {
    MipCache now(kBudget, std::make_unique<LruEvictionPolicy>(), MipCacheOptions{true, ArenaPrefault::kNow});
    EXPECT_EQ(now.stats().small_pool_warm_bytes, kBudget / 8);
  }
  MipCache cache(kBudget, std::make_unique<LruEvictionPolicy>(), MipCacheOptions{true, ArenaPrefault::kBackground});
  // Payloads taken (and written) while the pre-fault thread runs: past kWarmBytes some land in slabs that the
  // thread has claimed or is faulting in.
  std::vector<std::shared_ptr<CachedMip>> mips;
  for (uint32_t i = 0; i < 3000; ++i) {
    auto m = cache.make_payload(2048);
    ASSERT_NE(m, nullptr);
    ASSERT_TRUE(m->bytes.in_pool());
    std::memset(m->bytes.data(), static_cast<int>(i & 0xff), 2048);
    mips.push_back(std::move(m));
  }
  cache.wait_arena_warm();
  const MipCacheStats s = cache.stats();
  EXPECT_EQ(s.arena_warm_bytes, s.arena_bytes);
  EXPECT_EQ(s.small_pool_warm_bytes, s.small_pool_capacity);
  EXPECT_EQ(s.small_pool_prefault, s.small_pool_capacity);
  EXPECT_GE(s.small_pool_bytes, 3000u * 2048);
  for (uint32_t i = 0; i < mips.size(); ++i) {
    const std::byte* b = mips[i]->bytes.data();
    ASSERT_EQ(b[0], static_cast<std::byte>(i & 0xff)) << i;
    ASSERT_EQ(b[2047], static_cast<std::byte>(i & 0xff)) << i;
  }
}

TEST(SmallPayloadPoolTest, WarmStepsStopAtThePrefaultBoundAndAllocationPastItStillWorks) {
  SmallPayloadPool pool(64ull << 20);  // a 512 MiB cache's pool
  ASSERT_EQ(pool.prefault_bytes(), SmallPayloadPool::kPrefaultBytes);
  EXPECT_EQ(pool.bytes_warm(), SmallPayloadPool::kWarmBytes);
  int steps = 0;
  while (pool.warm_step()) ++steps;
  EXPECT_EQ(pool.bytes_warm(), SmallPayloadPool::kPrefaultBytes);  // not the whole 64 MiB
  EXPECT_FALSE(pool.warm_step());
  EXPECT_EQ(steps + 1, static_cast<int>((SmallPayloadPool::kPrefaultBytes - SmallPayloadPool::kWarmBytes) >> 20));
  // Slabs past the warm part are faulted in by allocate() itself, as before.
  std::vector<std::byte*> blocks;
  for (uint64_t b = 0; b < SmallPayloadPool::kPrefaultBytes + 4 * kSlab; b += 2048) {
    std::byte* p = pool.allocate(2048);
    ASSERT_NE(p, nullptr);
    p[0] = std::byte{1};
    blocks.push_back(p);
  }
  EXPECT_GT(pool.bytes_warm(), SmallPayloadPool::kPrefaultBytes);
  for (std::byte* p : blocks) pool.free(p, 2048);
}

}  // namespace
}  // namespace texstream::server
