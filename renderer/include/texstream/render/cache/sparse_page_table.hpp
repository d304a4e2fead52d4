#pragma once
// Which pages of the sparse cache images are bound, and to which memory slot (seed 000 §3.6 on a sparse
// partially-resident image). Pure bookkeeping: no Vulkan, no clock, one thread (the frame thread).
//
// Several images (one per texel format of the scene, each with its own page shape) share the one pool of
// slots: the budget is one, whatever format the pages hold (docs/design/cache_formats.md).
//
// A page is one sparse block of one mip level of one layer: `granularity` texels (the device's
// imageGranularity for the cache format: 128x128 for RGBA8 and 512x256 for BC1 with 64 KiB pages). Small
// regions of many textures fall into one page, so every page is reference-counted: each (texture, mip) whose
// region at that mip overlaps it holds one reference. The page is bound when the first reference is taken and
// unbound after the last one is dropped — but only once the GPU can no longer read it (the serial of the
// last submission that could have sampled it has completed).
//
// Memory: `slot_count` slots of one page each, carved out of a few large VkDeviceMemory blocks by the Vulkan
// side (SparseMemory). A bound page owns one slot, a slot backs at most one page, so
//   bound pages x page size <= slot_count x page size <= cache.memory_bytes   at all times.
// acquire() fails (and changes nothing) when the free slots do not cover the new pages: the caller frees some
// by evicting the oldest cache layer and calling reclaim().
//
// Binds and unbinds accumulate in one batch until take_batch(), so a streaming cycle issues one
// vkQueueBindSparse. A location unbound and bound again within one batch is only bound (the new slot
// replaces the old binding); a page bound and released again before its batch was submitted is never bound.
//
// Levels at or past `tail_first_level` live in the mip tail (devices that have one: not lavapipe): those are
// bound once for the whole image at start-up, and this table ignores them.
#include <cstddef>
#include <cstdint>
#include <unordered_map>
#include <unordered_set>
#include <vector>

namespace texstream::render {

struct PageGeometry {
  uint32_t layer_extent = 0;  // texels of a layer at mip 0 (power of two)
  uint32_t mip_levels = 0;    // levels of the cache image
  uint32_t layers = 0;
  uint32_t granularity_w = 0;  // texels per page (VkSparseImageFormatProperties::imageGranularity)
  uint32_t granularity_h = 0;
  uint32_t tail_first_level = 0;  // first level in the mip tail; == mip_levels when there is none
};

// The most images one table serves (one per texel format: rgba8, bc1, bc3, bc7).
inline constexpr uint32_t kMaxCacheImages = 4;

struct PageLocation {
  uint32_t layer = 0;
  uint32_t mip = 0;
  uint32_t x = 0;  // page column/row within the level
  uint32_t y = 0;
  uint32_t image = 0;  // which of the table's images
};

// A texture's rectangle in the image at mip 0 (CacheRegion's layer, origin, width, height). At level L it
// covers max(width >> L, block) x max(height >> L, block): a level of a BC1 texture is whole 4x4 blocks.
struct PageRect {
  uint32_t layer = 0;
  uint32_t x = 0;
  uint32_t y = 0;
  uint32_t width = 0;
  uint32_t height = 0;
  uint32_t block = 1;
  uint32_t image = 0;
};

struct PageBindOp {
  PageLocation page;
  bool bind = false;  // false: unbind
  uint32_t slot = 0;  // bind: the memory slot
};

struct PageTableStats {
  uint64_t pages_bound = 0;       // bind operations handed out in batches
  uint64_t pages_unbound = 0;     // unbind operations handed out in batches
  uint64_t pages_revived = 0;     // released pages taken again before they were unbound (no bind needed)
  uint64_t pages_shared = 0;      // acquisitions that found the page already bound for another region
  uint64_t acquire_failures = 0;  // acquire() calls refused for lack of free slots
};

class SparsePageTable {
 public:
  SparsePageTable(const PageGeometry& geometry, uint32_t slot_count);
  // One table over several images (PageRect::image and PageLocation::image index `images`), one slot pool.
  SparsePageTable(std::vector<PageGeometry> images, uint32_t slot_count);

  // Pages of the rectangle (origin, width x height at mip 0) at `mip`: each side shrinks with the level and is
  // at least one texel. Zero for levels in the mip tail.
  static uint32_t pages_of_region(const PageGeometry& g, const PageRect& rect, uint32_t mip);

  // Takes one reference on every page the rectangle covers at `mip`. False (nothing changed) when the free
  // slots cannot back the pages that would be new.
  bool acquire(const PageRect& rect, uint32_t mip);
  // Drops the references acquire() took. Pages reaching zero retire: submissions up to `serial` may still
  // read them, so they are unbound (and their slots reused) by reclaim() once `serial` has completed.
  void release(const PageRect& rect, uint32_t mip, uint64_t serial);
  // Submissions up to `completed_serial` are done: retired pages older than that are queued for unbinding and
  // their slots become free. Returns the number of slots freed.
  uint32_t reclaim(uint64_t completed_serial);
  // The binds and unbinds gathered since the last call; the caller submits them in one vkQueueBindSparse.
  std::vector<PageBindOp> take_batch();

  uint32_t slot_count() const { return slot_count_; }
  uint32_t free_slots() const { return static_cast<uint32_t>(free_.size()); }
  // Pages bound on the device once every batch taken so far has executed. Never above slot_count().
  uint64_t bound_pages() const { return device_bound_.size(); }
  uint64_t referenced_pages() const { return pages_.size() - retired_count_; }
  size_t pending_ops() const { return batch_.size(); }
  const PageTableStats& stats() const { return stats_; }
  const PageGeometry& geometry(uint32_t image = 0) const { return geometries_[image]; }
  uint32_t image_count() const { return static_cast<uint32_t>(geometries_.size()); }

 private:
  struct Page {
    uint32_t refs = 0;
    uint32_t slot = 0;
    uint64_t retire_serial = 0;  // refs == 0: the last submission that may read it
  };
  struct Op {
    bool bind;
    uint32_t slot;
  };
  uint64_t key(uint32_t image, uint32_t layer, uint32_t mip, uint32_t x, uint32_t y) const;
  PageLocation location(uint64_t key) const;
  // Calls f(key) for every page of the rectangle at `mip`.
  template <class F>
  void for_each_page(const PageRect& rect, uint32_t mip, F&& f) const;

  std::vector<PageGeometry> geometries_;
  uint32_t slot_count_;
  std::vector<uint32_t> free_;                // free slots; the lowest on top (blocks fill in order)
  std::unordered_map<uint64_t, Page> pages_;  // referenced or retired (slot still held)
  uint64_t retired_count_ = 0;
  std::unordered_map<uint64_t, Op> batch_;     // the last op per location since take_batch()
  std::unordered_set<uint64_t> device_bound_;  // bound once the taken batches have executed
  PageTableStats stats_;
};

}  // namespace texstream::render
