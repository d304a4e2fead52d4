// TextureCache's sparse residency (cache/residency_table.hpp) and the map under it and MipFades
// (cache/texture_index_map.hpp): the use list, entries going when idle, epochs never repeating, and the heap
// not growing with the textures that passed through (docs/design/host_memory.md: < 1 B per texture).
#include <gtest/gtest.h>

#include <bit>
#include <cstdint>
#include <random>
#include <unordered_map>
#include <vector>

#include "../support/heap_usage.hpp"
#include "texstream/render/cache/mip_fades.hpp"
#include "texstream/render/cache/residency_table.hpp"
#include "texstream/render/cache/texture_index_map.hpp"

namespace {

using texstream::TextureId;
using texstream::render::MipFades;
using texstream::render::Residency;
using texstream::render::ResidencyTable;
using texstream::render::TextureIndexMap;
namespace gpu = texstream::gpu;

std::vector<uint32_t> lru_order(const ResidencyTable& t) {
  std::vector<uint32_t> order;
  t.walk_lru([&](const Residency& r) {
    order.push_back(r.texture().value);
    return true;
  });
  return order;
}

using texstream::test::heap_bytes;

TEST(TextureIndexMap, AgreesWithAStandardMapThroughInsertsAndErases) {
  TextureIndexMap map(4);
  std::unordered_map<uint32_t, uint32_t> ref;
  std::mt19937 rng(7);
  // Ids in runs and spread out, so probe runs wrap around the table and backward shifts cross its end.
  std::uniform_int_distribution<uint32_t> id(0, 3000), op(0, 2);
  for (int i = 0; i < 200000; ++i) {
    const uint32_t t = i % 3 == 0 ? id(rng) * 1000003u : id(rng);
    if (op(rng) == 0 && ref.count(t) == 0) {
      map.insert(TextureId(t), static_cast<uint32_t>(i));
      ref[t] = static_cast<uint32_t>(i);
    } else if (op(rng) == 1) {
      EXPECT_EQ(map.erase(TextureId(t)), ref.erase(t) == 1);
    }
    const auto it = ref.find(t);
    ASSERT_EQ(map.find(TextureId(t)), it == ref.end() ? TextureIndexMap::kAbsent : it->second) << "id " << t;
  }
  ASSERT_EQ(map.size(), ref.size());
  for (const auto& [k, v] : ref) EXPECT_EQ(map.find(TextureId(k)), v);
  EXPECT_LE(map.slot_count(), 4 * std::bit_ceil(ref.size() + 1));  // half full at most, grown by doubling
}

TEST(ResidencyTable, UseListMovesAndUnlinksInOrder) {
  ResidencyTable table(100, 4);
  for (uint32_t t : {10u, 20u, 30u, 40u}) table.lru_append(table.get(TextureId(t)));
  EXPECT_EQ(lru_order(table), (std::vector<uint32_t>{10, 20, 30, 40}));
  table.lru_unlink(*table.find(TextureId(20)));
  Residency& first = *table.find(TextureId(10));  // used again: to the back
  table.lru_unlink(first);
  table.lru_append(first);
  EXPECT_EQ(lru_order(table), (std::vector<uint32_t>{30, 40, 10}));
  table.lru_unlink(*table.find(TextureId(10)));  // the tail
  table.lru_unlink(*table.find(TextureId(30)));  // the head
  EXPECT_EQ(lru_order(table), (std::vector<uint32_t>{40}));
  table.lru_unlink(*table.find(TextureId(20)));  // not listed: no-op
  EXPECT_EQ(lru_order(table), (std::vector<uint32_t>{40}));
  EXPECT_FALSE(table.find(TextureId(20))->listed());
  EXPECT_TRUE(table.find(TextureId(40))->listed());
}

TEST(ResidencyTable, AnEntryStaysWhileAnythingNeedsItAndItsEpochNeverComesBack) {
  ResidencyTable table(100, 2);
  EXPECT_EQ(table.find(TextureId(5)), nullptr);
  Residency& r = table.get(TextureId(5));
  EXPECT_EQ(&table.get(TextureId(5)), &r);
  const uint64_t first_epoch = r.epoch;
  r.copies = 1;
  EXPECT_FALSE(table.release_if_idle(r));
  r.copies = 0;
  r.bound = 1;
  EXPECT_FALSE(table.release_if_idle(r));
  r.bound = 0;
  r.mask = 4;
  EXPECT_FALSE(table.release_if_idle(r));
  r.mask = 0;
  table.lru_append(r);
  EXPECT_FALSE(table.release_if_idle(r));
  table.lru_unlink(r);
  EXPECT_TRUE(table.release_if_idle(r));
  EXPECT_EQ(table.find(TextureId(5)), nullptr);
  EXPECT_EQ(table.size(), 0u);
  // Back again (its pool entry reused): all zero, and an epoch it never had, so an old copy publishes nothing.
  Residency& again = table.get(TextureId(5));
  EXPECT_EQ(again.mask, 0u);
  EXPECT_EQ(again.wanted, 0u);
  EXPECT_GT(again.epoch, first_epoch);
  EXPECT_EQ(table.pool_size(), 1u);
  EXPECT_FALSE(table.evicted_before(TextureId(5)));
  table.mark_evicted(TextureId(5));
  EXPECT_TRUE(table.evicted_before(TextureId(5)));
  EXPECT_FALSE(table.evicted_before(TextureId(6)));
}

TEST(ResidencyTable, EntriesDoNotMoveWhenThePoolGrows) {
  ResidencyTable table(10000, 1);
  Residency& r = table.get(TextureId(0));
  r.mask = 7;
  for (uint32_t t = 1; t < 5000; ++t) table.get(TextureId(t)).mask = t;
  EXPECT_EQ(&r, table.find(TextureId(0)));
  EXPECT_EQ(r.mask, 7u);
  for (uint32_t t = 1; t < 5000; ++t) ASSERT_EQ(table.find(TextureId(t))->mask, t);
}

// A long path over a big city: 2,000,000 textures come into view, are placed, copied, resident, and evicted
// by use, with about 1,000 resident at a time. What is left on the heap afterwards must not grow with the
// 2 M (a dense 72 B entry per texture would be 144 MB; the reload bit is 0.125 B).
TEST(ResidencyTable, HeapDoesNotGrowWithTexturesThatPassedThrough) {
  constexpr uint32_t kTextures = 2'000'000;
  constexpr uint32_t kResident = 1000;
  const size_t before = heap_bytes();
  {
    ResidencyTable table(kTextures, 256);
    uint32_t cycle = 0;
    size_t peak = 0;
    for (uint32_t t = 0; t < kTextures; ++t) {
      ++cycle;
      // touch(): a texture not yet known has no entry and gets none.
      EXPECT_EQ(table.find(TextureId(t)), nullptr);
      // commit(): placed (in the use list) and a copy queued.
      Residency& r = table.get(TextureId(t));
      r.used_cycle = cycle;
      table.lru_append(r);
      ++r.copies;
      // prepare_uploads / on_submission_complete: bound, published, the copy let go.
      r.bound = 1;
      r.mask = 1;
      --r.copies;
      EXPECT_FALSE(table.release_if_idle(r));
      // evict(): the least recently used once the cache holds kResident.
      if (table.size() > kResident) {
        Residency* victim = nullptr;
        table.walk_lru([&](const Residency& v) {
          victim = table.find(v.texture());
          return false;
        });
        ASSERT_NE(victim, nullptr);
        ASSERT_EQ(victim->texture().value, t - kResident);
        table.mark_evicted(victim->texture());
        victim->mask = victim->bound = 0;
        victim->epoch = table.new_epoch();
        table.lru_unlink(*victim);
        ASSERT_TRUE(table.release_if_idle(*victim));
      }
      peak = std::max(peak, table.size());
    }
    EXPECT_EQ(table.size(), kResident);
    EXPECT_EQ(peak, kResident);
    EXPECT_LE(table.pool_size(), size_t{kResident + 1});
    const size_t grown = heap_bytes() - before;
    EXPECT_LT(grown, size_t{kTextures}) << grown << " bytes for " << kTextures << " textures";
    RecordProperty("heap_bytes_per_texture", std::to_string(static_cast<double>(grown) / kTextures));
  }
}

// The same for fades: textures fade in one after another, about 1,000 at a time.
TEST(MipFades, HeapDoesNotGrowWithTexturesThatFaded) {
  constexpr uint32_t kTextures = 1u << 20;
  std::vector<gpu::TextureGpu> table(kTextures);
  for (auto& t : table) {
    t.placement = {0, gpu::kNotResident, 0, 10};
    t.colour = {0, gpu::kNotResident, 0, 0};
  }
  const size_t before = heap_bytes();
  {
    MipFades fades(1.0);
    fades.advance(0.0, table);
    for (uint32_t t = 0; t < kTextures; ++t) {
      gpu::TextureGpu& e = table[t];
      e.placement.y = 3;
      fades.on_publish(t, e, gpu::kNotResident);
      if (t % 100 == 99) fades.advance(0.1, table);  // a fade lasts 10-11 advances: ~1,000 fading
      ASSERT_LE(fades.fading(), 1200u);
    }
    const size_t grown = heap_bytes() - before;
    EXPECT_LT(grown, size_t{kTextures}) << grown << " bytes for " << kTextures << " textures";
  }
}

}  // namespace
