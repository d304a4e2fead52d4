#pragma once
// Payloads below CacheArena::kMinBlock (the coarse mips: 1x1 to 32x16 RGBA8, 4x4 to 64x64 BC1) carved out of
// slabs of one reserved mapping that is faulted in ahead of use, instead of from the heap.
//
// Why (a free-list pop instead of a heap allocation that faulted pages in on the dispatcher; not from the
// cache's arena, which the large mips need): measured in docs/design/small_payload_pool.md.
//
// Size classes: the powers of two from kMinClass (16 B) to CacheArena::kMinBlock (4 KiB); a payload takes the
// smallest class that holds it (mip sizes are powers of two times 4 or 8 bytes, so nearly all fill their
// class exactly). Each class takes slabs of kSlabBytes as it needs them, carves its newest slab from the
// start, and keeps freed payloads on an intrusive free list (a free payload's first bytes hold the link; a payload in
// use is never written by the pool). The mapping goes away with the pool, once the cache and every payload (each holds
// the pool) are gone.
//
// Bounded: at most `max_bytes` of slabs (the cache passes a share of its budget: like the heap payloads they
// replace, they are memory beside the arena); past that allocate() returns nullptr and the caller uses the
// heap as before. Thread-safe (payloads are freed from any thread that drops the last reference).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <new>
#include <utility>

#include "texstream/server/cache/cache_arena.hpp"  // kMinBlock

namespace texstream::server {

class SmallPayloadPool {
 public:
  // Smallest class: 16 B (a 2x2 RGBA8 mip; the 4 B and 8 B mips round up — 12 bytes lost on a few
  // entries per texture).
  static constexpr uint64_t kMinClass = 16;
  // One slab: 16 pages; 4096 payloads of the smallest class, 16 of the largest. The arena's blocks are
  // powers of two, so a slab is one block with no waste.
  static constexpr uint64_t kSlabBytes = 64 << 10;

  // Faulted in when the pool is made (at most max_bytes): 2 MiB, ~8 ms on this machine (cache_arena.hpp),
  // the coarse mips of ~1500 textures.
  static constexpr uint64_t kWarmBytes = 2 << 20;

  // Reserves `max_bytes` (rounded down to slabs) of address space and faults in the first kWarmBytes. With
  // less than one slab, or no address space, the pool is empty: allocate() always returns nullptr.
  explicit SmallPayloadPool(uint64_t max_bytes);
  ~SmallPayloadPool();
  SmallPayloadPool(const SmallPayloadPool&) = delete;
  SmallPayloadPool& operator=(const SmallPayloadPool&) = delete;

  // Faulted in by warm_step() at most: with the cache's budget and the staging pool it must fit the 64 MiB the
  // server may use beside them (docs/config.md, server.ram_cache_bytes); the coarse mips of ~12000 textures.
  static constexpr uint64_t kPrefaultBytes = 16 << 20;

  // Faults in the next kWarmStepBytes of the pool not faulted in yet (one madvise, outside the pool's lock: a
  // slab handed out meanwhile is only written, as it would be anyway), up to prefault_bytes(). False once
  // that much is warm.
  // The cache arena's pre-fault thread calls it after the arena (CacheArena's then_warm): in a fresh server
  // the slabs taken while the cache first fills were faulted in by the dispatcher, one madvise per 64 KiB
  // slab (texstream-bench server --quick --phases misses, perf: clear_page and the fault path were ~5 % of
  // the dispatcher; 4 alternating runs with the pool warm: 2.70 us per mip against 2.82).
  bool warm_step();
  uint64_t bytes_warm() const;
  uint64_t prefault_bytes() const { return std::min(capacity_, kPrefaultBytes); }

  // True if `bytes` is a size this pool serves: 0 < bytes < CacheArena::kMinBlock.
  static bool serves(uint64_t bytes) { return bytes > 0 && bytes < CacheArena::kMinBlock; }
  // Memory for `bytes` (serves(bytes) must hold), or nullptr when every slab is taken and the class has no
  // free payload left.
  std::byte* allocate(uint64_t bytes);
  // Gives back memory from allocate(bytes) (the same `bytes`).
  void free(std::byte* p, uint64_t bytes);

  bool owns(const std::byte* p) const { return p >= base_ && p < base_ + capacity_; }
  uint64_t capacity() const { return capacity_; }
  uint64_t slab_bytes() const;    // slabs handed to the classes so far
  uint64_t bytes_in_use() const;  // class-rounded sizes of the payloads handed out and not freed

 private:
  static constexpr uint32_t kMinShift = 4;  // log2(kMinClass)
  // allocate() prefetches the first this many bytes of the class's next block (a control block of the cache
  // is ~100 bytes: two lines), in lines of kLineBytes.
  static constexpr uint64_t kPrefetchBytes = 128;
  static constexpr uint64_t kLineBytes = 64;
  static constexpr uint64_t kWarmStepBytes = 1 << 20;  // one warm_step(): ~4 ms on this machine
  static constexpr uint32_t kClasses = 9;              // 16 B .. 4 KiB
  static uint32_t class_of(uint64_t bytes);
  struct FreeNode {
    FreeNode* next;
  };

  std::byte* base_ = nullptr;
  uint64_t capacity_ = 0;
  uint64_t warm_ = 0;  // bytes from base_ faulted in so far
  mutable std::mutex mutex_;
  FreeNode* free_[kClasses] = {};  // freed payloads of each class
  // The part of each class's newest slab not handed out yet: [bump_, bump_end_) (empty: take a new slab).
  std::byte* bump_[kClasses] = {};
  std::byte* bump_end_[kClasses] = {};
  uint64_t slabs_used_ = 0;  // bytes from base_ handed to the classes
  uint64_t in_use_ = 0;
};

// A standard allocator over a SmallPayloadPool, for the cache's shared_ptr control blocks
// (std::allocate_shared): each cached mip's block (~100 bytes) was one more malloc growing the heap while
// misses filled the cache. Sizes the pool does not serve, or a pool that is full, go to operator new; the
// pool is kept alive by every copy (the control block keeps one).
template <class T>
class SmallPoolAllocator {
 public:
  using value_type = T;
  explicit SmallPoolAllocator(std::shared_ptr<SmallPayloadPool> pool) : pool_(std::move(pool)) {}
  template <class U>
  SmallPoolAllocator(const SmallPoolAllocator<U>& other) : pool_(other.pool()) {}  // NOLINT: rebinding

  T* allocate(size_t n) {
    static_assert(alignof(T) <= SmallPayloadPool::kMinClass, "pool memory is aligned to its 16-byte classes");
    const uint64_t bytes = uint64_t{n} * sizeof(T);
    if (SmallPayloadPool::serves(bytes)) {
      if (std::byte* p = pool_->allocate(bytes)) return reinterpret_cast<T*>(p);
    }
    return static_cast<T*>(::operator new(bytes));
  }
  void deallocate(T* p, size_t n) {
    auto* b = reinterpret_cast<std::byte*>(p);
    if (pool_->owns(b)) {
      pool_->free(b, uint64_t{n} * sizeof(T));
    } else {
      ::operator delete(p);
    }
  }
  const std::shared_ptr<SmallPayloadPool>& pool() const { return pool_; }
  template <class U>
  bool operator==(const SmallPoolAllocator<U>& other) const {
    return pool_ == other.pool();
  }

 private:
  std::shared_ptr<SmallPayloadPool> pool_;
};

}  // namespace texstream::server
