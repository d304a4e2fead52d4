#pragma once
// TextureCache's per-texture residency, kept only for textures that need it: resident, holding pages or a
// region in the use list, or with copies on their way. A texture without an entry is not resident and nothing
// refers to it; an entry goes as soon as that is true again, so the table's size follows the cache, not the
// scene (docs/design/host_memory.md: 0.125 B per texture not in view, for the reload statistic's bit).
//
// Entries live in a pool (chunks of kChunk, a free list) found through a TextureIndexMap; the use list (lru,
// least recently used first) links entries by pool index, so moving and unlinking stay O(1). Epochs come from
// one counter, so a texture's epoch never repeats even when its entry goes and comes back: a copy made under
// one epoch publishes nothing under another. Pure bookkeeping: no Vulkan, one thread.
#include <cstdint>
#include <memory>
#include <vector>

#include "texstream/common/ids.hpp"
#include "texstream/render/cache/cache_allocator.hpp"
#include "texstream/render/cache/texture_index_map.hpp"

namespace texstream::render {

class ResidencyTable;

// A texture's residency. Its fields are TextureCache's; the use-list links and the id are the table's.
struct Residency {
  uint32_t mask = 0;        // bit L: mip L is in the image and published
  uint32_t bound = 0;       // bit L: the pages under the region at mip L hold a reference for this texture
  uint64_t epoch = 0;       // ResidencyTable::new_epoch() at the entry's start and at each eviction
  CacheRegion region;       // valid while `bound` != 0 (the allocator forgets it when the layer goes)
  uint32_t used_cycle = 0;  // the touch() cycle that last used it (read for textures in the use list only)
  uint32_t copies = 0;      // copies of this texture the cache holds: queued, being bound, ready or in flight
  uint8_t wanted = 0;       // the finest level the last touch() wanted (floor of the desired level)

  TextureId texture() const { return TextureId(texture_); }
  bool listed() const { return lru_listed_; }

 private:
  friend class ResidencyTable;
  bool lru_listed_ = false;
  uint32_t texture_ = 0;
  uint32_t index_ = 0;     // in the pool
  uint32_t lru_prev_ = 0;  // pool index + 1 in the use list; 0: none
  uint32_t lru_next_ = 0;
};

class ResidencyTable {
 public:
  // `texture_count`: the scene's (sizes the reload bits); `expected_entries`: textures the cache may hold at
  // once (the pool and the map start with room for these and grow past them).
  ResidencyTable(size_t texture_count, size_t expected_entries);

  Residency* find(TextureId texture);
  const Residency* find(TextureId texture) const;
  // The texture's entry, made (all zero, a new epoch) when it has none. References stay valid until the
  // entry is released: the pool grows by chunks and never moves an entry.
  Residency& get(TextureId texture);
  // Drops the entry when nothing in it must be kept: not resident, no pages, not in the use list, no copies.
  // Returns whether it went (`r` is then dangling).
  bool release_if_idle(Residency& r);
  // An epoch no entry has had: for a texture evicted (its copies on the way must publish nothing).
  uint64_t new_epoch() { return ++epochs_; }

  // The use list, least recently used first.
  void lru_append(Residency& r);  // `r` must not be listed
  void lru_unlink(Residency& r);  // no-op when `r` is not listed
  // Calls f(const Residency&) for the listed entries, least recently used first, while it returns true.
  template <class F>
  void walk_lru(F&& f) const {
    for (uint32_t i = lru_head_; i != 0;) {
      const Residency& r = at(i - 1);
      const uint32_t next = r.lru_next_;
      if (!f(r)) return;
      i = next;
    }
  }

  // Whether the texture was evicted before (texture_reloads): one bit per texture, the only per-texture cost.
  void mark_evicted(TextureId texture) { evicted_before_[texture.value] = true; }
  bool evicted_before(TextureId texture) const { return evicted_before_[texture.value]; }

  size_t size() const { return index_.size(); }
  // Entries the pool holds, live or free: its peak size.
  size_t pool_size() const { return pool_entries_; }

 private:
  // 2^10 entries of 72 B a chunk (72 KiB): a few chunks for a cache of thousands of textures.
  static constexpr uint32_t kChunkShift = 10;
  static constexpr uint32_t kChunk = 1u << kChunkShift;

  Residency& at(uint32_t index) { return chunks_[index >> kChunkShift][index & (kChunk - 1)]; }
  const Residency& at(uint32_t index) const { return chunks_[index >> kChunkShift][index & (kChunk - 1)]; }

  TextureIndexMap index_;  // texture -> pool index
  std::vector<std::unique_ptr<Residency[]>> chunks_;
  uint32_t pool_entries_ = 0;  // entries handed out of the chunks so far (live or on free_)
  std::vector<uint32_t> free_;
  uint32_t lru_head_ = 0, lru_tail_ = 0;  // pool index + 1; 0 = empty
  uint64_t epochs_ = 0;
  std::vector<bool> evicted_before_;
};

}  // namespace texstream::render
