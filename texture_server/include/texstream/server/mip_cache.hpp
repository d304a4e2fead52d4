#pragma once
// The server's RAM cache of mips (DESIGN.md "Texture server": tiers; seed 002 §3.2: the Texture Server
// "manages an in-memory texture cache" and limits its size).
//
// Contract (OIIO ImageCache / Granite asset manager style):
// - Budget: the bytes of the cached payloads never exceed `budget_bytes`. A mip larger than the budget, or
//   one that cannot fit because everything that would have to go is pinned, is not admitted.
// - Pinning: lookup() hands out a shared_ptr; while anyone outside the cache holds one the entry is pinned
//   and is never evicted (so the budget counts only memory the cache could actually free). The cache keeps
//   one reference per entry; new references are made only under its lock, so use_count() == 1 seen under the
//   lock proves nobody else holds the entry.
// - One evictor: eviction happens only inside insert(), under the cache's lock.
// - Statistics: hits, misses, insertions, evictions, rejections, bytes and entries.
// Thread-safe. No syscall is made while the lock is held.
#include <cstdint>
#include <memory>
#include <mutex>
#include <type_traits>
#include <unordered_map>
#include <utility>
#include <vector>

#include "texstream/server/eviction_policy.hpp"
#include "texstream/server/mip_key.hpp"

namespace texstream::server {

// An allocator whose resize() leaves new elements default-initialised (for bytes: not written). A payload is
// always overwritten by a read or a copy right after it is sized; zeroing it first was one more full pass over
// every byte a miss delivers (measured with texstream-bench server: misses were 0.05-0.08x plain read()).
template <class T>
struct DefaultInitAllocator : std::allocator<T> {
  using value_type = T;
  template <class U>
  struct rebind {
    using other = DefaultInitAllocator<U>;
  };
  DefaultInitAllocator() = default;
  template <class U>
  DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept {}
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    std::construct_at(p, std::forward<Args>(args)...);
  }
};
using PayloadBytes = std::vector<std::byte, DefaultInitAllocator<std::byte>>;

// One cached mip: the payload exactly as it is handed to the renderer, and its checksum (so a hit does not
// hash again).
struct CachedMip {
  PayloadBytes bytes;
  uint64_t checksum = 0;
};

struct MipCacheStats {
  uint64_t hits = 0;
  uint64_t misses = 0;
  uint64_t insertions = 0;
  uint64_t evictions = 0;
  uint64_t rejections = 0;  // insert() refused: larger than the budget, or the rest was pinned
  uint64_t bytes = 0;       // payload bytes held now
  uint64_t entries = 0;
  uint64_t budget_bytes = 0;
};

class MipCache {
 public:
  MipCache(uint64_t budget_bytes, std::unique_ptr<EvictionPolicy> policy);

  // A pinned reference to the mip, or nullptr. Counts a hit or a miss.
  std::shared_ptr<const CachedMip> lookup(MipKey key);
  // True if the mip is cached now. Counts nothing (for peeking at whether a request is a fast hit).
  bool contains(MipKey key) const;
  // Admits `mip`, evicting unpinned entries in policy order until it fits. Returns false if it was not
  // admitted. A key already cached keeps its entry (two loads of the same mip raced; both are equal).
  bool insert(MipKey key, std::shared_ptr<const CachedMip> mip);
  // True if a mip of this size could ever be admitted (callers skip the private copy otherwise).
  bool admissible(uint64_t bytes) const { return budget_ > 0 && bytes <= budget_; }

  MipCacheStats stats() const;
  // Forwards the streaming-cycle clock to the policy (Eq. 4's frame count); `now` never goes back.
  void advance_clock(uint64_t now);

 private:
  const uint64_t budget_;
  mutable std::mutex mutex_;
  std::unique_ptr<EvictionPolicy> policy_;
  std::unordered_map<MipKey, std::shared_ptr<const CachedMip>, MipKeyHash> entries_;
  MipCacheStats stats_;
};

}  // namespace texstream::server
