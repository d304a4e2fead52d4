// SparsePageTable: pages of a region per level, sharing between small regions (bound once, reference-counted),
// unbinds deferred to the completed serial, the slot budget, and how one batch folds binds and unbinds.
#include <gtest/gtest.h>

#include <algorithm>

#include "texstream/render/cache/sparse_page_table.hpp"

using texstream::render::PageBindOp;
using texstream::render::PageGeometry;
using texstream::render::PageRect;
using texstream::render::SparsePageTable;

namespace {

// lavapipe's RGBA8 page: 64 KiB = 128 x 128 texels; a 512 layer has levels 512 .. 1 (10 levels), no mip tail.
PageGeometry rgba8_512(uint32_t layers = 4) { return PageGeometry{512, 10, layers, 128, 128, 10}; }

// A square region: what the seed's ring binds.
PageRect sq(uint32_t layer, uint32_t x, uint32_t y, uint32_t extent) { return PageRect{layer, x, y, extent, extent}; }

size_t count(const std::vector<PageBindOp>& ops, bool bind) {
  return static_cast<size_t>(
      std::count_if(ops.begin(), ops.end(), [&](const PageBindOp& o) { return o.bind == bind; }));
}

}  // namespace

TEST(SparsePageTable, ANonSquareRectangleCountsItsOwnPagesOnly) {
  const PageGeometry g = rgba8_512();
  // 512 x 128 at the top of a layer: one row of 4 pages, not the 16 of its 512² square.
  EXPECT_EQ(SparsePageTable::pages_of_region(g, PageRect{0, 0, 0, 512, 128}, 0), 4u);
  EXPECT_EQ(SparsePageTable::pages_of_region(g, PageRect{0, 0, 0, 128, 512}, 0), 4u);
  EXPECT_EQ(SparsePageTable::pages_of_region(g, PageRect{0, 0, 0, 512, 128}, 2), 1u);
  SparsePageTable t(g, 8);
  ASSERT_TRUE(t.acquire(PageRect{0, 0, 0, 512, 128}, 0));
  ASSERT_TRUE(t.acquire(PageRect{0, 0, 128, 512, 128}, 0));  // the next row: 4 new pages, 8 in all
  EXPECT_FALSE(t.acquire(PageRect{0, 0, 256, 128, 128}, 0));
  EXPECT_EQ(t.take_batch().size(), 8u);
}

TEST(SparsePageTable, PagesOfARegionShrinkWithTheLevelButNeverBelowOne) {
  const PageGeometry g = rgba8_512();
  EXPECT_EQ(SparsePageTable::pages_of_region(g, sq(0, 0, 0, 512), 0), 16u);  // 4 x 4 pages
  EXPECT_EQ(SparsePageTable::pages_of_region(g, sq(0, 0, 0, 512), 1), 4u);
  EXPECT_EQ(SparsePageTable::pages_of_region(g, sq(0, 0, 0, 512), 2), 1u);
  EXPECT_EQ(SparsePageTable::pages_of_region(g, sq(0, 0, 0, 512), 9), 1u);  // 1 x 1 level: a page of its own
  EXPECT_EQ(SparsePageTable::pages_of_region(g, sq(0, 256, 256, 256), 0), 4u);
  EXPECT_EQ(SparsePageTable::pages_of_region(g, sq(0, 64, 0, 64), 0), 1u);
  // BC1 pages (512 x 256 texels) are not square.
  const PageGeometry bc1{512, 10, 1, 512, 256, 10};
  EXPECT_EQ(SparsePageTable::pages_of_region(bc1, sq(0, 0, 0, 512), 0), 2u);
  EXPECT_EQ(SparsePageTable::pages_of_region(bc1, sq(0, 0, 256, 256), 0), 1u);
  // Levels in a mip tail are bound at start-up, not per region.
  const PageGeometry tail{512, 10, 1, 128, 128, 3};
  EXPECT_EQ(SparsePageTable::pages_of_region(tail, sq(0, 0, 0, 512), 3), 0u);
}

TEST(SparsePageTable, SmallRegionsShareOnePageBoundOnce) {
  SparsePageTable t(rgba8_512(), 64);
  // 16 textures of extent 128 in one 512 layer: at mip 0 each has its own page; from mip 2 (32 px) four
  // regions' levels (x0 = 0, 32, 64, 96 at mip 2) fall into the same page column.
  for (uint32_t i = 0; i < 16; ++i) ASSERT_TRUE(t.acquire(sq(0, (i % 4) * 128, (i / 4) * 128, 128), 2));
  auto batch = t.take_batch();
  EXPECT_EQ(count(batch, true), 1u);  // level 2 of the layer is 128 x 128: one page for all 16
  EXPECT_EQ(t.stats().pages_shared, 15u);
  EXPECT_EQ(t.bound_pages(), 1u);
  // Releasing 15 keeps it bound; the last release retires it, and it unbinds only after the serial completes.
  for (uint32_t i = 0; i < 15; ++i) t.release(sq(0, (i % 4) * 128, (i / 4) * 128, 128), 2, /*serial=*/7);
  EXPECT_EQ(t.reclaim(100), 0u);
  t.release(sq(0, 3 * 128, 3 * 128, 128), 2, /*serial=*/7);
  EXPECT_EQ(t.reclaim(6), 0u);  // submission 7 may still sample it
  EXPECT_TRUE(t.take_batch().empty());
  EXPECT_EQ(t.bound_pages(), 1u);
  EXPECT_EQ(t.reclaim(7), 1u);
  batch = t.take_batch();
  ASSERT_EQ(batch.size(), 1u);
  EXPECT_FALSE(batch[0].bind);
  EXPECT_EQ(t.bound_pages(), 0u);
  EXPECT_EQ(t.free_slots(), 64u);
}

TEST(SparsePageTable, AcquireBeyondTheSlotsFailsAndChangesNothing) {
  SparsePageTable t(rgba8_512(), 20);
  ASSERT_TRUE(t.acquire(sq(0, 0, 0, 512), 0));  // 16 pages
  EXPECT_EQ(t.free_slots(), 4u);
  EXPECT_FALSE(t.acquire(sq(1, 0, 0, 512), 0));  // 16 more do not fit
  EXPECT_EQ(t.free_slots(), 4u);
  EXPECT_EQ(t.stats().acquire_failures, 1u);
  EXPECT_TRUE(t.acquire(sq(1, 0, 0, 512), 1));  // 4 fit
  EXPECT_EQ(t.free_slots(), 0u);
  EXPECT_EQ(t.take_batch().size(), 20u);
  EXPECT_LE(t.bound_pages(), t.slot_count());
  // Freeing the first texture's level 0 makes room again once its serial completes.
  t.release(sq(0, 0, 0, 512), 0, 3);
  EXPECT_FALSE(t.acquire(sq(2, 0, 0, 512), 0));
  EXPECT_EQ(t.reclaim(3), 16u);
  EXPECT_TRUE(t.acquire(sq(2, 0, 0, 512), 0));
  auto batch = t.take_batch();
  EXPECT_EQ(count(batch, false), 16u);
  EXPECT_EQ(count(batch, true), 16u);
  EXPECT_EQ(t.bound_pages(), 20u);
}

TEST(SparsePageTable, UnbindAndRebindOfOneLocationInABatchIsOneBind) {
  SparsePageTable t(rgba8_512(), 8);
  ASSERT_TRUE(t.acquire(sq(0, 0, 0, 128), 0));
  ASSERT_EQ(t.take_batch().size(), 1u);
  t.release(sq(0, 0, 0, 128), 0, 1);
  ASSERT_EQ(t.reclaim(1), 1u);
  ASSERT_TRUE(t.acquire(sq(0, 0, 0, 64), 0));  // a new texture in the recycled layer, same page
  auto batch = t.take_batch();
  ASSERT_EQ(batch.size(), 1u);
  EXPECT_TRUE(batch[0].bind);
  EXPECT_EQ(t.bound_pages(), 1u);
}

TEST(SparsePageTable, PageBoundAndFreedBeforeItsBatchNeverReachesTheDevice) {
  SparsePageTable t(rgba8_512(), 8);
  ASSERT_TRUE(t.acquire(sq(0, 0, 0, 128), 0));
  t.release(sq(0, 0, 0, 128), 0, 0);
  ASSERT_EQ(t.reclaim(0), 1u);
  EXPECT_TRUE(t.take_batch().empty());
  EXPECT_EQ(t.bound_pages(), 0u);
  EXPECT_EQ(t.free_slots(), 8u);
}

TEST(SparsePageTable, RetiredPageTakenAgainIsRevivedWithoutABind) {
  SparsePageTable t(rgba8_512(), 8);
  ASSERT_TRUE(t.acquire(sq(0, 0, 0, 128), 0));
  ASSERT_EQ(t.take_batch().size(), 1u);
  t.release(sq(0, 0, 0, 128), 0, 5);
  ASSERT_TRUE(t.acquire(sq(0, 0, 0, 128), 0));  // before serial 5 completed: same slot, no new bind
  EXPECT_TRUE(t.take_batch().empty());
  EXPECT_EQ(t.stats().pages_revived, 1u);
  EXPECT_EQ(t.reclaim(100), 0u);  // referenced again: not unbound
  EXPECT_EQ(t.bound_pages(), 1u);
}

TEST(SparsePageTable, RandomWorkloadNeverExceedsTheSlots) {
  // A deterministic pseudo-random mix of acquires and releases: bound pages never exceed the slots, and every
  // slot comes back when everything is released.
  const PageGeometry g = rgba8_512(8);
  SparsePageTable t(g, 40);
  struct Held {
    uint32_t layer, x, y, extent, mip;
  };
  std::vector<Held> held;
  uint64_t state = 12345, serial = 0;
  auto next = [&] {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<uint32_t>(state >> 33);
  };
  for (int step = 0; step < 5000; ++step) {
    if (held.empty() || next() % 3 != 0) {
      const uint32_t extent = 32u << (next() % 5);  // 32 .. 512
      const uint32_t per_row = 512 / extent;
      const uint32_t idx = next() % (per_row * per_row);
      Held h{next() % 8, (idx % per_row) * extent, (idx / per_row) * extent, extent, next() % 10};
      if (t.acquire(sq(h.layer, h.x, h.y, h.extent), h.mip)) held.push_back(h);
    } else {
      const size_t i = next() % held.size();
      t.release(sq(held[i].layer, held[i].x, held[i].y, held[i].extent), held[i].mip, serial);
      held.erase(held.begin() + static_cast<long>(i));
    }
    if (step % 7 == 0) {
      t.reclaim(serial);
      t.take_batch();
      ++serial;
      ASSERT_LE(t.bound_pages(), t.slot_count());
    }
  }
  for (const Held& h : held) t.release(sq(h.layer, h.x, h.y, h.extent), h.mip, serial);
  t.reclaim(serial);
  t.take_batch();
  EXPECT_EQ(t.bound_pages(), 0u);
  EXPECT_EQ(t.free_slots(), 40u);
}

// Several images (one per texel format) over one slot pool: a page of one image and the page at the same
// place of another are different pages, each image counts pages by its own page shape, and the slots the first
// image holds are not there for the second (one budget).
TEST(SparsePageTable, ImagesOfSeveralFormatsShareOneSlotPool) {
  const PageGeometry rgba8 = rgba8_512();
  const PageGeometry bc1{512, 10, 4, 512, 256, 10};  // NVIDIA's BC1 page: 512 x 256 texels
  SparsePageTable t({rgba8, bc1}, 6);
  EXPECT_EQ(t.image_count(), 2u);
  PageRect a = sq(0, 0, 0, 256);  // RGBA8: 2 x 2 pages at level 0
  PageRect b = sq(0, 0, 0, 256);
  b.image = 1;  // BC1: one page at level 0
  EXPECT_EQ(SparsePageTable::pages_of_region(t.geometry(0), a, 0), 4u);
  EXPECT_EQ(SparsePageTable::pages_of_region(t.geometry(1), b, 0), 1u);
  ASSERT_TRUE(t.acquire(a, 0));
  ASSERT_TRUE(t.acquire(b, 0));  // not shared with image 0's page at (0, 0)
  EXPECT_EQ(t.free_slots(), 1u);
  PageRect b2 = sq(0, 0, 256, 256);
  b2.image = 1;
  ASSERT_TRUE(t.acquire(b2, 0));
  PageRect b3 = sq(1, 0, 0, 256);
  b3.image = 1;
  EXPECT_FALSE(t.acquire(b3, 0)) << "image 0 holds four of the six slots";
  const auto ops = t.take_batch();
  ASSERT_EQ(ops.size(), 6u);
  EXPECT_EQ(std::count_if(ops.begin(), ops.end(), [](const PageBindOp& o) { return o.page.image == 1; }), 2);
  EXPECT_TRUE(std::is_sorted(ops.begin(), ops.end(),
                             [](const PageBindOp& x, const PageBindOp& y) { return x.page.image < y.page.image; }));
  // Image 0's pages go (once serial 1 has completed): image 1 gets the slots.
  t.release(a, 0, 1);
  EXPECT_EQ(t.reclaim(1), 4u);
  EXPECT_TRUE(t.acquire(b3, 0));
  const auto next = t.take_batch();
  EXPECT_EQ(count(next, false), 4u);
  EXPECT_EQ(count(next, true), 1u);
  EXPECT_EQ(t.bound_pages(), 3u);
}
