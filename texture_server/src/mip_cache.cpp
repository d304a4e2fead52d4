#include "texstream/server/fault_point.hpp"
#include "texstream/server/mip_cache.hpp"

#include <cstring>

#include "texstream/common/contract.hpp"

namespace texstream::server {

MipCache::MipCache(uint64_t budget_bytes, std::unique_ptr<EvictionPolicy> policy, MipCacheOptions options)
    : budget_(budget_bytes), policy_(std::move(policy)) {
  TS_ASSERT(policy_ != nullptr, "MipCache needs an eviction policy");
  stats_.budget_bytes = budget_;
  // The arena is the budget itself, so arena payloads can never hold more memory than the budget allows.
  if (options.arena && budget_ >= CacheArena::kMinBlock) {
    arena_ = std::make_shared<CacheArena>(budget_, options.prefault);
    if (arena_->capacity() == 0) arena_.reset();  // no address space: heap payloads, as without the option
  }
}

std::shared_ptr<const CachedMip> MipCache::lookup(MipKey key) {
  std::lock_guard lock(mutex_);
  auto it = entries_.find(key);
  if (it == entries_.end()) {
    ++stats_.misses;
    return nullptr;
  }
  ++stats_.hits;
  policy_->touch(it->second.node);
  return it->second.mip;  // the copy is the pin: made under the lock (see the header's contract)
}

std::optional<CachedCopy> MipCache::copy_into(MipKey key, std::span<std::byte> dst) {
  std::lock_guard lock(mutex_);
  auto it = entries_.find(key);
  if (it == entries_.end()) {
    ++stats_.misses;
    return std::nullopt;
  }
  const CachedMip& mip = *it->second.mip;
  TS_ASSERT(mip.bytes.size() <= dst.size(), "cached mip of %zu bytes does not fit a buffer of %zu",
            mip.bytes.size(), dst.size());
  ++stats_.hits;
  policy_->touch(it->second.node);
  // Copied under the lock: nothing can evict the entry meanwhile, so no pin (no reference-count traffic) is
  // needed. The longest hold is one slot-sized copy (1 MiB: ~100 µs), which only delays a worker's insert.
  copy_into_slot(dst.data(), mip.bytes.data(), mip.bytes.size());  // kSlotWrite halfway
  return CachedCopy{mip.bytes.size(), mip.checksum};
}

bool MipCache::contains(MipKey key) const {
  std::lock_guard lock(mutex_);
  return entries_.count(key) != 0;
}

bool MipCache::evict_one(std::vector<std::shared_ptr<const CachedMip>>& evicted) {
  // Only entries nobody outside holds may go: use_count() == 1 is the cache's own reference. Counts only fall
  // concurrently (new references are made under this lock), so a stale read can only keep an entry.
  const auto evictable = [this](MipKey k) {
    auto it = entries_.find(k);
    return it != entries_.end() && it->second.mip.use_count() == 1;
  };
  const std::optional<MipKey> victim = policy_->pick_victim(evictable);
  if (!victim) return false;
  auto it = entries_.find(*victim);
  stats_.bytes -= it->second.mip->bytes.size();
  if (is_overflow(it->second.mip->bytes)) overflow_bytes_ -= it->second.mip->bytes.size();
  fault_point(FaultPoint::kEviction);  // victim picked, not yet erased
  policy_->erase(it->second.node);
  evicted.push_back(std::move(it->second.mip));
  entries_.erase(it);
  ++stats_.evictions;
  return true;
}

std::shared_ptr<CachedMip> MipCache::make_payload(uint64_t bytes) {
  if (!admissible(bytes)) return nullptr;
  if (!arena_ || bytes < CacheArena::kMinBlock || CacheArena::block_bytes(bytes) > arena_->largest_block()) {
    auto heap = std::make_shared<CachedMip>();
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
        auto heap = std::make_shared<CachedMip>();
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
  auto mip = std::make_shared<CachedMip>();
  mip->bytes = PayloadBytes(arena_, block, bytes);
  return mip;
}

bool MipCache::insert(MipKey key, std::shared_ptr<const CachedMip> mip) {
  TS_ASSERT(mip != nullptr, "inserting a null mip");
  const uint64_t size = mip->bytes.size();
  // Declared before the lock: evicted payloads are freed after it is released (a large free() is a munmap).
  std::vector<std::shared_ptr<const CachedMip>> evicted;
  std::lock_guard lock(mutex_);
  auto [it, fresh] = entries_.try_emplace(key, Entry{nullptr, nullptr});
  if (!fresh) {
    policy_->touch(it->second.node);
    return true;  // two loads of the same mip raced; `mip` is freed after the lock (a parameter)
  }
  // The slot is reserved in the map before evicting, so evict_one() must not pick it: it has no policy node
  // and a null mip, and the policy does not know the key yet, so it never can.
  const auto give_up = [&] {
    entries_.erase(key);
    ++stats_.rejections;
    stats_.entries = entries_.size();
    return false;
  };
  if (!admissible(size)) return give_up();
  while (stats_.bytes + size > budget_) {
    // Everything left is pinned (at most one entry per worker plus the dispatcher): refuse, stay in budget.
    if (!evict_one(evicted)) return give_up();
  }
  // `it` is still valid: erasing other elements invalidates only their own iterators.
  if (is_overflow(mip->bytes)) overflow_bytes_ += size;
  it->second.mip = std::move(mip);
  it->second.node = policy_->on_insert(key);
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
  }
  return s;
}

}  // namespace texstream::server
