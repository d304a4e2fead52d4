#include "texstream/server/mip_cache.hpp"

#include "texstream/common/contract.hpp"

namespace texstream::server {

MipCache::MipCache(uint64_t budget_bytes, std::unique_ptr<EvictionPolicy> policy)
    : budget_(budget_bytes), policy_(std::move(policy)) {
  TS_ASSERT(policy_ != nullptr, "MipCache needs an eviction policy");
  stats_.budget_bytes = budget_;
}

std::shared_ptr<const CachedMip> MipCache::lookup(MipKey key) {
  std::lock_guard lock(mutex_);
  auto it = entries_.find(key);
  if (it == entries_.end()) {
    ++stats_.misses;
    return nullptr;
  }
  ++stats_.hits;
  policy_->on_access(key);
  return it->second;  // the copy is the pin: made under the lock (see the header's contract)
}

bool MipCache::contains(MipKey key) const {
  std::lock_guard lock(mutex_);
  return entries_.count(key) != 0;
}

bool MipCache::insert(MipKey key, std::shared_ptr<const CachedMip> mip) {
  TS_ASSERT(mip != nullptr, "inserting a null mip");
  const uint64_t size = mip->bytes.size();
  // Declared before the lock: evicted payloads are freed after it is released (a large free() is a munmap).
  std::vector<std::shared_ptr<const CachedMip>> evicted;
  std::lock_guard lock(mutex_);
  if (entries_.count(key) != 0) {
    policy_->on_access(key);
    return true;
  }
  if (!admissible(size)) {
    ++stats_.rejections;
    return false;
  }
  // Only entries nobody outside holds may go: use_count() == 1 is the cache's own reference. Counts only fall
  // concurrently (new references are made under this lock), so a stale read can only keep an entry.
  const auto evictable = [this](MipKey k) {
    auto it = entries_.find(k);
    return it != entries_.end() && it->second.use_count() == 1;
  };
  while (stats_.bytes + size > budget_) {
    const std::optional<MipKey> victim = policy_->pick_victim(evictable);
    if (!victim) {
      // Everything left is pinned (at most one entry per worker plus the dispatcher): refuse, stay in budget.
      ++stats_.rejections;
      stats_.entries = entries_.size();
      return false;
    }
    auto it = entries_.find(*victim);
    stats_.bytes -= it->second->bytes.size();
    evicted.push_back(std::move(it->second));
    entries_.erase(it);
    policy_->on_erase(*victim);
    ++stats_.evictions;
  }
  entries_.emplace(key, std::move(mip));
  policy_->on_insert(key);
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

MipCacheStats MipCache::stats() const {
  std::lock_guard lock(mutex_);
  MipCacheStats s = stats_;
  s.entries = entries_.size();
  return s;
}

}  // namespace texstream::server
