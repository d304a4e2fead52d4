#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <random>
#include <unordered_map>
#include <vector>

#include "texstream/server/cache/lru_eviction_policy.hpp"
#include "texstream/server/cache/mip_cache.hpp"
#include "texstream/server/cache/mip_cache_table.hpp"

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

// Pins are counted (eviction skips the per-entry check while none is out): a pin and its copies keep the entry,
// letting the last one go makes it evictable again, and a pin may outlive the cache.
TEST(MipCacheTest, APinLetGoMakesItsEntryEvictableAgainAndAPinMayOutliveTheCache) {
  std::shared_ptr<const CachedMip> outliving;
  {
    MipCache cache = make_cache(200);
    ASSERT_TRUE(cache.insert(key(1), mip_of(100, 1)));
    ASSERT_TRUE(cache.insert(key(2), mip_of(100, 2)));
    {
      const auto pin = cache.lookup(key(1));
      const auto copy = pin;  // NOLINT(performance-unnecessary-copy-initialization): a second holder
      EXPECT_FALSE(cache.insert(key(3), mip_of(150, 3)));  // 2 goes; 1 is pinned, so 150 bytes never fit
      EXPECT_TRUE(cache.contains(key(1)));
    }
    ASSERT_TRUE(cache.insert(key(3), mip_of(150, 3)));  // no pin out: 1 goes
    EXPECT_FALSE(cache.contains(key(1)));
    outliving = cache.lookup(key(3));
  }
  ASSERT_NE(outliving, nullptr);
  EXPECT_EQ(outliving->bytes.size(), 150u);
  EXPECT_EQ(outliving->bytes.front(), std::byte{3});
  outliving.reset();  // counts the pin off on a counter the cache no longer owns alone (ASan: no use after free)
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

TEST(MipCacheTest, CopyIntoCopiesTouchesAndCountsLikeLookup) {
  MipCache cache = make_cache(300);
  std::vector<std::byte> dst(200, std::byte{0});
  EXPECT_FALSE(cache.copy_into(key(1), dst).has_value());
  ASSERT_TRUE(cache.insert(key(1), mip_of(100, 1)));
  ASSERT_TRUE(cache.insert(key(2), mip_of(100, 2)));
  ASSERT_TRUE(cache.insert(key(3), mip_of(100, 3)));
  const std::optional<CachedCopy> hit = cache.copy_into(key(1), dst);
  ASSERT_TRUE(hit.has_value());
  EXPECT_EQ(hit->bytes, 100u);
  EXPECT_EQ(hit->checksum, 1u);
  EXPECT_EQ(dst[0], std::byte{1});
  EXPECT_EQ(dst[99], std::byte{1});
  EXPECT_EQ(dst[100], std::byte{0});  // nothing past the mip is written
  // The copy touched 1: the LRU victim is now 2.
  ASSERT_TRUE(cache.insert(key(4), mip_of(100, 4)));
  EXPECT_TRUE(cache.contains(key(1)));
  EXPECT_FALSE(cache.contains(key(2)));
  const MipCacheStats s = cache.stats();
  EXPECT_EQ(s.hits, 1u);
  EXPECT_EQ(s.misses, 1u);
}

MipCache make_arena_cache(uint64_t budget) {
  return MipCache(budget, std::make_unique<LruEvictionPolicy>(), MipCacheOptions{true, ArenaPrefault::kNone});
}

TEST(MipCacheTest, ArenaPayloadsComeFromTheArenaAndSmallOnesFromTheHeap) {
  MipCache cache = make_arena_cache(64 << 10);
  auto big = cache.make_payload(16 << 10);
  ASSERT_NE(big, nullptr);
  EXPECT_TRUE(big->bytes.in_arena());
  EXPECT_EQ(big->bytes.size(), 16u << 10);
  auto small = cache.make_payload(100);
  ASSERT_NE(small, nullptr);
  EXPECT_FALSE(small->bytes.in_arena());
  EXPECT_EQ(cache.make_payload((64 << 10) + 1), nullptr);  // over the budget: not admissible
  EXPECT_EQ(cache.stats().arena_in_use_bytes, 16u << 10);
  big.reset();  // a payload never inserted goes back to the arena
  EXPECT_EQ(cache.stats().arena_in_use_bytes, 0u);
  MipCache heap_only = make_cache(64 << 10);
  auto h = heap_only.make_payload(16 << 10);
  ASSERT_NE(h, nullptr);
  EXPECT_FALSE(h->bytes.in_arena());
  EXPECT_EQ(heap_only.stats().arena_bytes, 0u);
}

// A miss's whole life with the arena: payload, fill, insert, hit; when the arena is full make_payload evicts
// in policy order, and the budget and the arena's capacity both hold throughout.
TEST(MipCacheTest, ArenaMissesEvictInPolicyOrderAndNeverOverflow) {
  constexpr uint64_t kBudget = 256 << 10;
  MipCache cache = make_arena_cache(kBudget);
  std::mt19937 rng(5);
  std::vector<std::byte> dst(64 << 10);
  for (uint32_t i = 0; i < 3000; ++i) {
    const MipKey k = key(rng() % 200, 0);
    if (cache.copy_into(k, dst)) {
      ASSERT_EQ(dst[0], static_cast<std::byte>(k.texture().value & 0xff));
      continue;
    }
    const uint64_t bytes = uint64_t{4096} << (k.texture().value % 5);  // 4..64 KiB, as mips are
    std::shared_ptr<CachedMip> p = cache.make_payload(bytes);
    ASSERT_NE(p, nullptr) << "nothing is pinned, so the arena must find room";
    std::memset(p->bytes.data(), static_cast<int>(k.texture().value & 0xff), bytes);
    p->checksum = k.texture().value;
    ASSERT_TRUE(cache.insert(k, std::move(p)));
    const MipCacheStats s = cache.stats();
    ASSERT_LE(s.bytes, kBudget);
    ASSERT_LE(s.arena_in_use_bytes, s.arena_bytes);
    // Powers of two >= 4 KiB: no rounding, so the arena holds exactly its entries' bytes; what the arena's
    // fragmentation pushed to the heap stays within its share of the budget.
    ASSERT_LE(s.arena_in_use_bytes, s.bytes);
    ASSERT_LE(s.bytes - s.arena_in_use_bytes, kBudget / 8);
  }
  const MipCacheStats s = cache.stats();
  EXPECT_GT(s.hits, 0u);
  EXPECT_GT(s.evictions, 0u);
  EXPECT_EQ(s.arena_fallbacks, 0u);
}

TEST(MipCacheTest, ArenaFullOfPinnedEntriesGivesNoPayloadInsteadOfOverflowing) {
  MipCache cache = make_arena_cache(16 << 10);
  std::vector<std::shared_ptr<const CachedMip>> pins;
  for (uint32_t i = 0; i < 4; ++i) {
    auto p = cache.make_payload(4096);
    ASSERT_NE(p, nullptr);
    ASSERT_TRUE(cache.insert(key(i), p));
    pins.push_back(std::move(p));  // held outside the cache: pinned
  }
  EXPECT_EQ(cache.make_payload(4096), nullptr);
  EXPECT_EQ(cache.stats().arena_fallbacks, 1u);
  pins.pop_back();  // key(3) unpinned: it can go
  EXPECT_NE(cache.make_payload(4096), nullptr);
  EXPECT_FALSE(cache.contains(key(3)));
}

// The index under a random mix of inserts and erases, against std::unordered_map: growth past the initial
// size, long probe runs and backward-shift deletion (an erase in the middle of a run must leave every later
// key of the run findable, and no stale copy of a moved entry behind).
TEST(MipCacheTableTest, AgreesWithAReferenceMapUnderRandomInsertsAndErases) {
  // 8 textures x 4 mips stay within the initial 64 slots, so probe runs often wrap around the table's end;
  // 301 x 4 make it grow several times. A table sized up front (as MipCache sizes it for its budget) must
  // behave the same without growing.
  for (const size_t expected : {size_t{0}, size_t{2000}})
    for (const uint32_t textures : {8u, 301u}) {
      MipCacheTable table(expected);
      std::unordered_map<uint64_t, uint64_t> reference;  // key value -> size
      std::mt19937 rng(11);
      // Few keys: keys come back after being erased, and runs of colliding homes form.
      std::uniform_int_distribution<uint32_t> texture(0, textures - 1), mip(0, 3), action(0, 2);
      for (int step = 0; step < 20000; ++step) {
        const MipKey k = key(texture(rng), mip(rng));
        const bool present = reference.count(k.value) != 0;
        if (action(rng) != 0 && !present) {
          MipCacheSlot slot;
          slot.key = k;
          slot.size = static_cast<uint64_t>(step) + 1;
          slot.mip = mip_of(1, 1);
          MipCacheSlot* placed = table.insert(std::move(slot));
          ASSERT_EQ(placed->key, k);
          reference[k.value] = static_cast<uint64_t>(step) + 1;
        } else {
          std::shared_ptr<const CachedMip> out;
          ASSERT_EQ(table.erase(k, out), present) << "step " << step;
          EXPECT_EQ(out != nullptr, present);
          reference.erase(k.value);
        }
        ASSERT_EQ(table.size(), reference.size());
        if (textures < 100 || step % 97 == 0) {
          for (uint32_t t = 0; t < textures; ++t) {
            for (uint32_t m = 0; m <= 3; ++m) {
              const MipCacheSlot* e = table.find(key(t, m));
              auto it = reference.find(key(t, m).value);
              ASSERT_EQ(e != nullptr, it != reference.end()) << "step " << step << " texture " << t << " mip " << m;
              if (e) {
                EXPECT_EQ(e->size, it->second);
              }
            }
          }
        }
      }
    }
}

TEST(MipCacheTest, CopyIntoServesTheEntryStillPresentAfterOthersAreEvicted) {
  // Evictions move entries inside the index (backward shift): the survivors must still copy their own bytes.
  MipCache cache = make_cache(64 * 100);
  for (uint32_t t = 0; t < 200; ++t) ASSERT_TRUE(cache.insert(key(t), mip_of(100, static_cast<uint8_t>(t))));
  const MipCacheStats s = cache.stats();
  EXPECT_LE(s.bytes, 64u * 100u);
  EXPECT_EQ(s.entries, 64u);
  std::vector<std::byte> dst(100);
  for (uint32_t t = 0; t < 200; ++t) {
    const std::optional<CachedCopy> c = cache.copy_into(key(t), dst);
    ASSERT_EQ(c.has_value(), t >= 136) << "texture " << t;  // LRU: the last 64 inserted survive
    if (!c) continue;
    EXPECT_EQ(c->bytes, 100u);
    EXPECT_EQ(c->checksum, t);
    EXPECT_EQ(dst[0], std::byte{static_cast<uint8_t>(t)});
    EXPECT_EQ(dst[99], std::byte{static_cast<uint8_t>(t)});
  }
}

}  // namespace
}  // namespace texstream::server
