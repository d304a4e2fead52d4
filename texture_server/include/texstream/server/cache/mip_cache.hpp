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
//   lock proves nobody else holds the entry. lookup()'s pins are counted (pins_): with none out, which is
//   always the server's case (its hits are copy_into(), copied under the lock), eviction asks no entry.
// - One evictor: eviction happens only inside insert() and make_payload(), under the cache's lock.
// - Statistics: hits, misses, insertions, evictions, rejections, bytes and entries.
// - Warm arena (MipCacheOptions::arena): payloads of ≥ 4 KiB come from one pre-faulted mapping of the budget
//   (cache_arena.hpp) through make_payload(), so a miss never page-faults fresh memory; payloads made by the
//   caller stay on the heap, and so may up to 1/8 of the budget when the arena is too
//   fragmented for a block (see kHeapOverflowDivisor). The arena is resident for its whole capacity once warm.
//   Payloads below 4 KiB come from warm slabs beside the arena (small_payload_pool.hpp), up to
//   budget / kSmallPoolDivisor, then from the heap as before; the memory they hold is counted in the budget
//   like any payload's, the pool's unused slab space is not (at most budget / kSmallPoolDivisor).
// Thread-safe. No syscall is made while the lock is held.
//
// The hit path: copy_into() finds, touches and copies a mip into the caller's buffer under one lock with one
// hash lookup and no allocation (the pinned lookup() costs a second reference-count round trip); the index
// (mip_cache_table.hpp) keeps the payload pointer, size and checksum inline, so a hit reads one index slot.
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <utility>
#include <vector>

#include "texstream/server/cache/cache_arena.hpp"
#include "texstream/server/cache/eviction_policy.hpp"
#include "texstream/server/cache/mip_cache_table.hpp"
#include "texstream/server/cache/mip_key.hpp"
#include "texstream/server/cache/payload_bytes.hpp"
#include "texstream/server/cache/small_payload_pool.hpp"

namespace texstream::server {

// One cached mip: the payload exactly as it is handed to the renderer, and its checksum (so a hit does not
// hash again).
struct CachedMip {
  PayloadBytes bytes;
  uint64_t checksum = 0;
};

// What copy_into() copied.
struct CachedCopy {
  uint64_t bytes = 0;
  uint64_t checksum = 0;
  bool first_use_of_prefetch = false;  // the entry was inserted as `prefetched` and this is its first hit
};

// How a mip a load brought in was used before it reaches the cache (MipCache::insert_loaded()).
enum class LoadedUse : uint8_t {
  kAsked,      // the mip the load was for (its lookup already counted the miss)
  kReadAhead,  // read along, not served yet: inserted prefetched (read amplification counts it when served)
  kServed,     // read along and already served from the read's own bytes: counted as a prefetched entry's
               // first hit, exactly as if it had been inserted first and then copied out (copy_into())
};

struct LoadedMip {
  MipKey key;
  std::shared_ptr<const CachedMip> mip;
  LoadedUse use = LoadedUse::kAsked;
};

struct MipCacheOptions {
  bool arena = false;  // payloads from make_payload() come from a warm arena of the budget's size
  ArenaPrefault prefault = ArenaPrefault::kBackground;
};

struct MipCacheStats {
  uint64_t hits = 0;
  uint64_t misses = 0;
  uint64_t insertions = 0;
  uint64_t evictions = 0;
  uint64_t rejections = 0;          // insert() refused: larger than the budget, or the rest was pinned
  uint64_t prefetched = 0;          // entries inserted ahead of any request (a coarse-tail read)
  uint64_t prefetch_hits = 0;       // of the hits: first uses of such entries (the rest of the hits were asked before)
  uint64_t prefetched_bytes = 0;    // their payload bytes
  uint64_t prefetch_hit_bytes = 0;  // the payload bytes of those first uses
  uint64_t bytes = 0;               // payload bytes held now
  uint64_t entries = 0;
  uint64_t budget_bytes = 0;
  uint64_t arena_bytes = 0;            // the arena's capacity (0: no arena)
  uint64_t arena_warm_bytes = 0;       // of which pre-faulted so far
  uint64_t arena_in_use_bytes = 0;     // blocks handed out (rounded to powers of two)
  uint64_t arena_evictions = 0;        // evictions make_payload() made to find a free block (fragmentation)
  uint64_t arena_fallbacks = 0;        // make_payload() found no block even after evicting (all pinned)
  uint64_t arena_overflows = 0;        // payloads put on the heap because no arena block was free
  uint64_t small_pool_bytes = 0;       // slabs of the small payload pool in use (payloads < 4 KiB)
  uint64_t small_pool_capacity = 0;    // the pool's reserved bytes (0: no pool)
  uint64_t small_pool_prefault = 0;    // of which the arena's pre-fault faults in (SmallPayloadPool)
  uint64_t small_pool_warm_bytes = 0;  // of which faulted in so far
};

class MipCache {
 public:
  MipCache(uint64_t budget_bytes, std::unique_ptr<EvictionPolicy> policy, MipCacheOptions options = {});

  // A pinned reference to the mip, or nullptr. Counts a hit or a miss.
  std::shared_ptr<const CachedMip> lookup(MipKey key);
  // True if the mip is cached now. Counts nothing (for peeking at whether a request is a fast hit).
  bool contains(MipKey key) const;
  // Admits `mip`, evicting unpinned entries in policy order until it fits. Returns false if it was not
  // admitted. A key already cached keeps its entry (two loads of the same mip raced; both are equal).
  // `prefetched`: read ahead of any request (see CachedCopy::first_use_of_prefetch).
  bool insert(MipKey key, std::shared_ptr<const CachedMip> mip, bool prefetched = false);
  // insert() of several mips under one lock (a coarse-tail read brings up to a dozen); returns how many were
  // admitted. Each entry is admitted or refused exactly as insert() would.
  size_t insert_all(std::span<std::pair<MipKey, std::shared_ptr<const CachedMip>>> mips, bool prefetched);
  // The mips of one read (a load and the levels it brought along) under one lock, each admitted or refused
  // exactly as insert() would (kReadAhead ones marked prefetched). A kServed mip counts a hit and a prefetch
  // hit even when it is not admitted: it was delivered. Returns how many were admitted.
  size_t insert_loaded(std::span<LoadedMip> mips);
  // Bit l set: level l of `texture` is cached now (l < min(levels, 32)). One lock for all levels; counts
  // nothing.
  uint32_t cached_levels(TextureId texture, uint32_t levels) const;
  // True if a mip of this size could ever be admitted (callers skip the private copy otherwise).
  bool admissible(uint64_t bytes) const { return budget_ > 0 && bytes <= budget_; }

  // The hit path: if `key` is cached, copies it into the front of `dst`, touches it and counts a hit; else
  // counts a miss and returns nullopt. One lock, one hash lookup, no allocation. `dst` must hold the mip
  // (the dispatcher sizes slots for any mip of the scene).
  // `prefetch_next`: a hint, the key most likely copied next (the scheduler's next request). Under the same
  // lock its payload (if cached) starts loading into the CPU cache before this copy, so the next copy starts
  // on cached lines instead of waiting for DRAM (texstream-bench server: hits are ~10 KiB payloads spread
  // over the arena; a small gain, see copy_into()). Counts nothing for it.
  std::optional<CachedCopy> copy_into(MipKey key, std::span<std::byte> dst,
                                      std::optional<MipKey> prefetch_next = std::nullopt);
  // Starts loading the index slots of `keys` into the CPU cache (a hint: counts nothing, changes nothing). The
  // dispatcher calls it once per drained batch of requests, so that the index lookups of the batch's hits
  // overlap instead of each waiting for DRAM in copy_into().
  void prefetch_index(std::span<const MipKey> keys) const;
  // A payload of exactly `bytes` for a miss to read into and then insert(): from the warm arena when there is
  // one and `bytes` ≥ CacheArena::kMinBlock (evicting unpinned entries in policy order until a block is
  // free), else from the heap. nullptr when the mip is not admissible, or when the arena has no block even
  // with everything unpinned gone (the caller then reads straight into its slot and caches nothing).
  std::shared_ptr<CachedMip> make_payload(uint64_t bytes);
  // Blocks until the arena's background pre-fault is done (benchmarks that measure warm misses).
  void wait_arena_warm();

  MipCacheStats stats() const;
  // Forwards the streaming-cycle clock to the policy (Eq. 4's frame count); `now` never goes back.
  void advance_clock(uint64_t now);

 private:
  // Removes one unpinned entry in policy order (lock held); its reference goes to `evicted`. False if every
  // entry is pinned.
  bool evict_one(std::vector<std::shared_ptr<const CachedMip>>& evicted);
  // An empty CachedMip for make_payload() (its shared_ptr's block from the small payload pool if any).
  std::shared_ptr<CachedMip> new_cached_mip() const;
  // insert()'s body (lock held).
  bool insert_locked(MipKey key, std::shared_ptr<const CachedMip> mip, bool prefetched,
                     std::vector<std::shared_ptr<const CachedMip>>& evicted);

  // When the arena has no free block of a size (buddy fragmentation) although the byte budget has room, up to
  // budget / this many bytes of arena-sized payloads go on the heap before make_payload() evicts for a block.
  // Measured on texstream-bench server's trace (level policy, 30 MB): hit rate 0.595 without an arena, 0.532
  // when make_payload() evicted at once, 0.572 with this heap share. Those heap bytes are outside the pre-faulted
  // arena: the resident set of the cache can reach budget * (1 + 1/8) plus its sub-4-KiB payloads.
  static constexpr uint64_t kHeapOverflowDivisor = 8;
  // Payloads below CacheArena::kMinBlock come from a pool of warm slabs beside the arena
  // (small_payload_pool.hpp), at most budget / this many bytes of them; past that from the heap, as before.
  // The coarse mips of a texture are ~1/3 of its 4 KiB mip: far less than 1/8 of a cache of whole mip chains.
  static constexpr uint64_t kSmallPoolDivisor = 8;
  // The index is sized at construction for a budget full of mips of this size (the 64x64 RGBA8 tail mip,
  // MipLoader::kTailMipBytes), so that it does not grow — and fault in fresh memory — while misses fill the
  // cache (texstream-bench server, misses: the index's doublings were ~1/4 of the dispatcher's page faults).
  // Capped at kMaxPresizedEntries (a 8 MiB index).
  static constexpr uint64_t kPresizeEntryBytes = 16 << 10;
  static constexpr uint64_t kMaxPresizedEntries = 1 << 16;

  const uint64_t budget_;
  // A heap payload the arena would have held (overflow_bytes_ counts those among the entries).
  bool is_overflow(const PayloadBytes& p) const { return arena_ && !p.in_arena() && p.size() >= CacheArena::kMinBlock; }
  uint64_t overflow_bytes_ = 0;
  std::shared_ptr<CacheArena> arena_;             // shared with the payloads it backs: they may outlive the cache
  std::shared_ptr<SmallPayloadPool> small_pool_;  // with the arena only (null without one)
  // new_cached_mip()'s allocator, made once: a temporary one per payload was two more atomic reference-count
  // changes of the pool's shared_ptr per cached mip (texstream-bench server, misses, perf: the larger part of
  // new_cached_mip(), itself ~3 % of the dispatcher).
  std::optional<SmallPoolAllocator<CachedMip>> block_allocator_;
  mutable std::mutex mutex_;
  std::unique_ptr<EvictionPolicy> policy_;
  // lookup()'s pins not released yet. Each pin is a shared_ptr of its own whose deleter counts it off (and then
  // drops its reference to the entry), so the counter can outlive the cache. While it is 0 no entry has a
  // reference but the cache's, and evict_one() asks the policy for its victim without checking each candidate
  // (a hash probe and a reference-count read per eviction: 8 % of the loader's time in misses into a full
  // cache, perf; ~10 % of the time of such misses in all, see evict_one()).
  std::shared_ptr<std::atomic<uint64_t>> pins_ = std::make_shared<std::atomic<uint64_t>>(0);
  MipCacheTable entries_;  // each entry keeps the policy node of its key: a hit touches it without a lookup
  MipCacheStats stats_;
};

}  // namespace texstream::server
