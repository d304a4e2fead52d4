#include "texstream/server/cache/mip_cache.hpp"
#include "texstream/server/support/fault_point.hpp"

#include <algorithm>
#include <cstring>

#include "texstream/common/contract.hpp"

namespace texstream::server {

MipCache::MipCache(uint64_t budget_bytes, std::unique_ptr<EvictionPolicy> policy, MipCacheOptions options)
    : budget_(budget_bytes),
      policy_(std::move(policy)),
      entries_(static_cast<size_t>(std::min(budget_bytes / kPresizeEntryBytes, kMaxPresizedEntries))) {
  TS_ASSERT(policy_ != nullptr, "MipCache needs an eviction policy");
  policy_->reserve(static_cast<size_t>(std::min(budget_bytes / kPresizeEntryBytes, kMaxPresizedEntries)));
  stats_.budget_bytes = budget_;
  // The arena is the budget itself, so arena payloads can never hold more memory than the budget allows.
  if (options.arena && budget_ >= CacheArena::kMinBlock) {
    // The pool's pages are faulted in after the arena's, by the arena's pre-fault (SmallPayloadPool::warm_step).
    auto pool = std::make_shared<SmallPayloadPool>(budget_ / kSmallPoolDivisor);
    arena_ = std::make_shared<CacheArena>(budget_, options.prefault, [pool] { return pool->warm_step(); });
    if (arena_->capacity() == 0) {
      arena_.reset();  // no address space: heap payloads, as without the option
    } else {
      small_pool_ = std::move(pool);
      block_allocator_.emplace(small_pool_);
    }
  }
}

std::shared_ptr<const CachedMip> MipCache::lookup(MipKey key) {
  std::lock_guard lock(mutex_);
  MipCacheSlot* e = entries_.find(key);
  if (e == nullptr) {
    ++stats_.misses;
    return nullptr;
  }
  ++stats_.hits;
  policy_->touch(e->node);
  // The pin: a reference to the entry (made under the lock, see the header's contract), inside a shared_ptr
  // whose deleter counts the pin off before that reference goes.
  pins_->fetch_add(1, std::memory_order_relaxed);  // relaxed: read under this lock, which orders it
  return std::shared_ptr<const CachedMip>(e->mip.get(), [entry = e->mip, pins = pins_](const CachedMip*) {
    pins->fetch_sub(1, std::memory_order_release);  // pairs with evict_one()'s acquire: the holder is done
  });
}

std::optional<CachedCopy> MipCache::copy_into(MipKey key, std::span<std::byte> dst,
                                              std::optional<MipKey> prefetch_next) {
  std::lock_guard lock(mutex_);
  if (prefetch_next) {
    // The first kPrefetchBytes of the next payload, one line at a time; the hardware prefetcher follows once
    // its copy streams. texstream-bench server, hit phase, 6 runs each: no prefetch 0.44, 2 KiB 0.46, 4 KiB
    // 0.45, 16 KiB 0.43 of memcpy (16 KiB of prefetches fill the line-fill buffers and stall the copy).
    constexpr uint64_t kPrefetchBytes = 2 << 10;
    constexpr uint64_t kLine = 64;
    if (const MipCacheSlot* n = entries_.find(*prefetch_next)) {
      for (uint64_t o = 0; o < std::min(n->size, kPrefetchBytes); o += kLine) __builtin_prefetch(n->data + o, 0, 3);
    }
  }
  MipCacheSlot* e = entries_.find(key);
  if (e == nullptr) {
    ++stats_.misses;
    return std::nullopt;
  }
  TS_ASSERT(e->size <= dst.size(), "cached mip of %llu bytes does not fit a buffer of %zu",
            static_cast<unsigned long long>(e->size), dst.size());
  ++stats_.hits;
  policy_->touch(e->node);
  // Copied under the lock: nothing can evict the entry meanwhile, so no pin (no reference-count traffic) is
  // needed. The longest hold is one slot-sized copy (1 MiB: ~100 µs), which only delays a worker's insert.
  // The payload's pointer, size and checksum are the index's copies: the CachedMip is not dereferenced.
  copy_into_slot(dst.data(), e->data, e->size);  // kSlotWrite halfway
  const bool first_use = e->prefetched;
  e->prefetched = false;
  stats_.prefetch_hits += first_use ? 1 : 0;
  stats_.prefetch_hit_bytes += first_use ? e->size : 0;
  return CachedCopy{e->size, e->checksum, first_use};
}

void MipCache::prefetch_index(std::span<const MipKey> keys) const {
  if (keys.empty()) return;
  std::lock_guard lock(mutex_);  // the table may grow under a worker's insert: its slots are read under the lock
  for (const MipKey k : keys) entries_.prefetch(k);
}

bool MipCache::contains(MipKey key) const {
  std::lock_guard lock(mutex_);
  return entries_.find(key) != nullptr;
}

bool MipCache::evict_one(std::vector<std::shared_ptr<const CachedMip>>& evicted) {
  // Only entries nobody outside holds may go: use_count() == 1 is the cache's own reference. Counts only fall
  // concurrently (new references are made under this lock), so a stale read can only keep an entry.
  // With no lookup() pin out, nothing outside holds an entry: no candidate needs asking (the server's case).
  const auto evictable = [this](MipKey k) {
    const MipCacheSlot* e = entries_.find(k);
    return e != nullptr && e->mip.use_count() == 1;
  };
  const bool pinned_some = pins_->load(std::memory_order_acquire) != 0;
  const std::optional<MipKey> victim =
      pinned_some ? policy_->pick_victim(evictable) : policy_->pick_victim(std::function<bool(MipKey)>{});
  if (!victim) return false;
  MipCacheSlot* e = entries_.find(*victim);
  TS_ASSERT(e != nullptr, "the eviction policy picked a key the cache does not hold");
  stats_.bytes -= e->size;
  if (is_overflow(e->mip->bytes)) overflow_bytes_ -= e->size;
  fault_point(FaultPoint::kEviction);  // victim picked, not yet erased
  policy_->erase(e->node);
  std::shared_ptr<const CachedMip> gone;
  entries_.erase(e, gone);  // the entry found above: no second lookup
  evicted.push_back(std::move(gone));
  ++stats_.evictions;
  return true;
}

std::shared_ptr<CachedMip> MipCache::new_cached_mip() const {
  // The control block and CachedMip in one allocation, from the small payload pool when there is one.
  if (small_pool_) return std::allocate_shared<CachedMip>(*block_allocator_);
  return std::make_shared<CachedMip>();
}

std::shared_ptr<CachedMip> MipCache::make_payload(uint64_t bytes) {
  if (!admissible(bytes)) return nullptr;
  if (small_pool_ && SmallPayloadPool::serves(bytes)) {
    // Pre-faulted slab memory (see small_payload_pool.hpp); the pool at its bound or no slab: the heap.
    if (std::byte* p = small_pool_->allocate(bytes)) {
      auto mip = new_cached_mip();
      mip->bytes = PayloadBytes(small_pool_, p, bytes);
      return mip;
    }
  }
  if (!arena_ || bytes < CacheArena::kMinBlock || CacheArena::block_bytes(bytes) > arena_->largest_block()) {
    auto heap = new_cached_mip();
    heap->bytes.resize(bytes);
    return heap;
  }
  // Heap payloads evicted on the way are freed after the lock is released (a large free() is a munmap).
  std::vector<std::shared_ptr<const CachedMip>> evicted;
  std::byte* block = nullptr;
  {
    std::lock_guard lock(mutex_);
    while ((block = arena_->allocate(bytes)) == nullptr) {
      // No free block of this size although the byte budget may have room (buddy fragmentation): a bounded
      // share of the budget may live on the heap instead of evicting entries the policy wants to keep.
      if (overflow_bytes_ + bytes <= budget_ / kHeapOverflowDivisor) {
        ++stats_.arena_overflows;
        stats_.entries = entries_.size();
        auto heap = new_cached_mip();
        heap->bytes.resize(bytes);  // no syscall for sizes the heap already holds; rare (see the divisor)
        return heap;
      }
      if (!evict_one(evicted)) {
        ++stats_.arena_fallbacks;
        stats_.entries = entries_.size();
        return nullptr;
      }
      ++stats_.arena_evictions;
      // An arena victim's block must go back now (no syscall: the arena's free list) for the retry to see it.
      if (evicted.back()->bytes.in_arena()) evicted.pop_back();
    }
    stats_.entries = entries_.size();
  }
  auto mip = new_cached_mip();
  mip->bytes = PayloadBytes(arena_, block, bytes);
  return mip;
}

bool MipCache::insert(MipKey key, std::shared_ptr<const CachedMip> mip, bool prefetched) {
  // Declared before the lock: evicted payloads are freed after it is released (a large free() is a munmap).
  std::vector<std::shared_ptr<const CachedMip>> evicted;
  std::lock_guard lock(mutex_);
  return insert_locked(key, std::move(mip), prefetched, evicted);
}

size_t MipCache::insert_all(std::span<std::pair<MipKey, std::shared_ptr<const CachedMip>>> mips, bool prefetched) {
  std::vector<std::shared_ptr<const CachedMip>> evicted;  // freed after the lock, as in insert()
  size_t admitted = 0;
  std::lock_guard lock(mutex_);
  for (auto& [key, mip] : mips) admitted += insert_locked(key, std::move(mip), prefetched, evicted) ? 1 : 0;
  return admitted;
}

size_t MipCache::insert_loaded(std::span<LoadedMip> mips) {
  std::vector<std::shared_ptr<const CachedMip>> evicted;  // freed after the lock, as in insert()
  size_t admitted = 0;
  std::lock_guard lock(mutex_);
  for (LoadedMip& m : mips) {
    if (m.use == LoadedUse::kServed) {
      ++stats_.hits;
      ++stats_.prefetch_hits;
      ++stats_.prefetched;  // it was read ahead (stats_.prefetched counts entries read ahead of a request)
      stats_.prefetch_hit_bytes += m.mip->bytes.size();
      stats_.prefetched_bytes += m.mip->bytes.size();
    }
    admitted += insert_locked(m.key, std::move(m.mip), m.use == LoadedUse::kReadAhead, evicted) ? 1 : 0;
  }
  return admitted;
}

uint32_t MipCache::cached_levels(TextureId texture, uint32_t levels) const {
  uint32_t mask = 0;
  const uint32_t n = std::min<uint32_t>(levels, 32);
  std::lock_guard lock(mutex_);
  // Each level's slot is a cache miss of its own (the levels hash far apart): ask for all of them first so
  // the misses overlap (texstream-bench server, misses: this loop was ~2.5 % of the dispatcher, one miss per
  // level after the other).
  for (uint32_t l = 0; l < n; ++l) entries_.prefetch(MipKey(texture, MipLevel(l)));
  for (uint32_t l = 0; l < n; ++l) {
    if (entries_.find(MipKey(texture, MipLevel(l))) != nullptr) mask |= 1u << l;
  }
  return mask;
}

bool MipCache::insert_locked(MipKey key, std::shared_ptr<const CachedMip> mip, bool prefetched,
                             std::vector<std::shared_ptr<const CachedMip>>& evicted) {
  TS_ASSERT(mip != nullptr, "inserting a null mip");
  const uint64_t size = mip->bytes.size();
  if (MipCacheSlot* e = entries_.find(key)) {
    policy_->touch(e->node);
    return true;  // two loads of the same mip raced; `mip` is freed after the lock (a parameter)
  }
  // The key is not in the index (nor in the policy) while evicting, so evict_one() can never pick it; it is
  // added only once the budget has room (erasing moves index entries, so nothing is reserved up front).
  const auto give_up = [&] {
    ++stats_.rejections;
    stats_.entries = entries_.size();
    return false;
  };
  if (!admissible(size)) return give_up();
  while (stats_.bytes + size > budget_) {
    // Everything left is pinned (held through lookup()): refuse, stay in budget.
    if (!evict_one(evicted)) return give_up();
  }
  if (is_overflow(mip->bytes)) overflow_bytes_ += size;
  MipCacheSlot slot;
  slot.key = key;
  slot.data = mip->bytes.data();
  slot.size = size;
  slot.checksum = mip->checksum;
  // Read-ahead (prefetched) mips enter as recently used, like asked ones. Tried: at the cold end of their
  // level, as old as its stalest entry (prefetches at low priority, as a page cache's inactive list does):
  // texstream-bench server --quick, trace, 3 alternating runs each: hit rate 0.835-0.843 against 0.890-0.892.
  // They are the renderer's next requests (it refines one level at a time), not speculative bytes.
  slot.node = policy_->insert_new(key);  // not in entries_ (checked above), so not in the policy either
  slot.mip = std::move(mip);
  slot.prefetched = prefetched;
  stats_.prefetched += prefetched ? 1 : 0;
  stats_.prefetched_bytes += prefetched ? size : 0;
  entries_.insert(std::move(slot));
  stats_.bytes += size;
  ++stats_.insertions;
  stats_.entries = entries_.size();
  TS_ASSERT(stats_.bytes <= budget_, "cache holds %llu bytes over its budget %llu",
            static_cast<unsigned long long>(stats_.bytes), static_cast<unsigned long long>(budget_));
  return true;
}

void MipCache::advance_clock(uint64_t now) {
  std::lock_guard lock(mutex_);
  policy_->on_tick(now);
}

void MipCache::wait_arena_warm() {
  if (arena_) arena_->wait_warm();
}

MipCacheStats MipCache::stats() const {
  std::lock_guard lock(mutex_);
  MipCacheStats s = stats_;
  s.entries = entries_.size();
  if (arena_) {
    s.arena_bytes = arena_->capacity();
    s.arena_warm_bytes = arena_->bytes_warm();
    s.arena_in_use_bytes = arena_->bytes_in_use();
    s.small_pool_bytes = small_pool_->slab_bytes();
    s.small_pool_capacity = small_pool_->capacity();
    s.small_pool_prefault = small_pool_->prefault_bytes();
    s.small_pool_warm_bytes = small_pool_->bytes_warm();
  }
  return s;
}

}  // namespace texstream::server
