#pragma once
// Warm memory for the RAM cache's payloads: one anonymous mapping of the cache's byte budget, faulted in once
// (at creation, or by a background thread at idle priority) and then reused for every miss, so a miss reads
// straight into memory the kernel has already mapped.
//
// Why: on this machine a first touch costs ~4 µs per 4 KiB page (MAP_POPULATE of 256 MiB took 1.03 s; with
// transparent huge pages 12.7 s), so a miss of a 256 KiB mip into freshly malloc'ed memory paid ~250 µs of
// faults for a ~30 µs pread (texstream-bench server: the loader alone 7–11 µs/mip vs 2.5 µs into warm memory).
//
// Allocator: binary buddy over blocks of kMinBlock (4 KiB) to the largest power of two that fits. Mips are
// powers of two times a block size (4 B texels, 8 B BC1 blocks), so a mip ≥ 4 KiB fills its block exactly
// (non-power-of-two textures round up: at most 2x). Payloads below kMinBlock are not for the arena (the
// caller keeps them on the heap, where malloc's small bins reuse warm memory anyway). A free block's order is
// kept out of band (one byte per 4 KiB), never in the payload memory itself.
//
// RSS: a pre-faulted arena is resident for its whole capacity from the moment it is warm, used or not; the
// server's budget is therefore memory it really holds (the bound is budget + staging + 64 MB).
// Thread-safe (its own mutex; the cache calls it under the cache's lock, frees come from any thread).
#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <set>
#include <thread>
#include <vector>

namespace texstream::server {

enum class ArenaPrefault {
  kNone,        // pages are faulted by the first payload written into them
  kNow,         // faulted in the constructor (blocks it: ~4 ms per MiB on this machine)
  kBackground,  // faulted by a thread at SCHED_IDLE from low to high addresses; allocation prefers low ones
};

class CacheArena {
 public:
  static constexpr uint64_t kMinBlock = 4096;  // one page: smaller payloads stay on the heap
  static constexpr uint32_t kMaxOrders = 40;   // 4 KiB << 39: far beyond any budget

  // `capacity` is rounded down to kMinBlock. A capacity below kMinBlock gives an empty arena (every
  // allocate() fails). The mapping is reserved without swap accounting (MAP_NORESERVE) and never grows.
  //
  // `then_warm`, if given, is more memory to fault in after the arena's own pages, on the same thread (or in the
  // constructor with kNow): it is called until it returns false (each call one bounded step) or the arena goes.
  // MipCache passes its small-payload pool's (small_payload_pool.hpp).
  CacheArena(uint64_t capacity, ArenaPrefault prefault, std::function<bool()> then_warm = {});
  ~CacheArena();
  CacheArena(const CacheArena&) = delete;
  CacheArena& operator=(const CacheArena&) = delete;

  // A block of at least `bytes` (rounded up to a power of two ≥ kMinBlock), or nullptr when no free block is
  // large enough (the caller evicts and tries again). `bytes` must be > 0.
  std::byte* allocate(uint64_t bytes);
  // Returns a block from allocate() (`bytes` as given to it).
  void free(std::byte* block, uint64_t bytes);
  // True if `p` lies in this arena's mapping.
  bool owns(const std::byte* p) const { return p >= base_ && p < base_ + capacity_; }

  uint64_t capacity() const { return capacity_; }
  // The largest block the arena can ever hand out (the largest power of two in the capacity).
  uint64_t largest_block() const { return capacity_ == 0 ? 0 : std::bit_floor(capacity_); }
  uint64_t bytes_in_use() const;                                                 // rounded block sizes
  uint64_t bytes_warm() const { return warm_.load(std::memory_order_relaxed); }  // relaxed: a progress gauge
  // Blocks the caller until the background pre-fault is done (tests and benchmarks: measure warm misses).
  void wait_warm();
  // Rounded size of a block for `bytes`.
  static uint64_t block_bytes(uint64_t bytes);

 private:
  static constexpr uint8_t kFreeBit = 0x80;  // in order_of_: the block starting here is free

  uint32_t order_for(uint64_t bytes) const;
  uint64_t index_of(const std::byte* p) const { return static_cast<uint64_t>(p - base_) / kMinBlock; }
  void push_free(uint64_t index, uint32_t order);
  void remove_free(uint64_t index, uint32_t order);
  void prefault_range(uint64_t from, uint64_t to);
  void warm_in_background();
  void warm_then();  // then_warm_'s steps, until it is done or the arena goes

  std::byte* base_ = nullptr;
  uint64_t capacity_ = 0;
  uint64_t mapped_ = 0;
  mutable std::mutex mutex_;
  // Per order, the free blocks (min-block indices), ordered: allocation takes the lowest address, so the arena
  // fills from the bottom, where the background pre-fault has already been.
  std::vector<std::set<uint64_t>> free_;
  std::vector<uint8_t> order_of_;  // per min block: order | kFreeBit at a block's first index; 0xff elsewhere
  uint64_t in_use_ = 0;
  std::atomic<uint64_t> warm_{0};
  std::atomic<bool> stop_{false};
  std::function<bool()> then_warm_;
  std::thread warmer_;
};

}  // namespace texstream::server
