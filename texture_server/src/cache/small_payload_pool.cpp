#include "texstream/server/cache/small_payload_pool.hpp"

#include <sys/mman.h>

#include <algorithm>
#include <bit>

#include "texstream/common/contract.hpp"

namespace texstream::server {

static_assert(SmallPayloadPool::kSlabBytes % CacheArena::kMinBlock == 0, "a slab is whole pages");
static_assert((SmallPayloadPool::kMinClass << 8) == CacheArena::kMinBlock, "9 classes: 16 B .. 4 KiB");

namespace {

// Faults in [p, p + bytes) writable: one madvise (Linux 5.14); older kernels get one written byte per page.
void populate(std::byte* p, uint64_t bytes) {
  if (::madvise(p, bytes, MADV_POPULATE_WRITE) == 0) return;
  for (uint64_t o = 0; o < bytes; o += CacheArena::kMinBlock) reinterpret_cast<volatile char*>(p)[o] = 0;
}

}  // namespace

SmallPayloadPool::SmallPayloadPool(uint64_t max_bytes) {
  capacity_ = max_bytes / kSlabBytes * kSlabBytes;
  if (capacity_ == 0) return;
  void* p = ::mmap(nullptr, capacity_, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
  if (p == MAP_FAILED) {
    capacity_ = 0;  // no address space: every small payload goes to the heap
    return;
  }
  base_ = static_cast<std::byte*>(p);
  ::madvise(base_, capacity_, MADV_NOHUGEPAGE);  // as the arena: populating huge pages was 12x slower here
  warm_ = std::min(capacity_, kWarmBytes);
  populate(base_, warm_);
}

SmallPayloadPool::~SmallPayloadPool() {
  if (base_) ::munmap(base_, capacity_);
}

uint32_t SmallPayloadPool::class_of(uint64_t bytes) {
  const uint64_t rounded = std::bit_ceil(std::max(bytes, kMinClass));
  return static_cast<uint32_t>(std::countr_zero(rounded)) - kMinShift;
}

std::byte* SmallPayloadPool::allocate(uint64_t bytes) {
  TS_ASSERT(serves(bytes), "the small payload pool does not serve %llu bytes", static_cast<unsigned long long>(bytes));
  const uint32_t c = class_of(bytes);
  const uint64_t size = kMinClass << c;
  std::lock_guard lock(mutex_);
  in_use_ += size;
  if (FreeNode* n = free_[c]) {  // a freed payload first (its line is likely still in the CPU cache)
    free_[c] = n->next;
    return reinterpret_cast<std::byte*>(n);
  }
  if (bump_[c] == bump_end_[c]) {
    if (slabs_used_ + kSlabBytes > capacity_) {
      in_use_ -= size;
      return nullptr;
    }
    std::byte* slab = base_ + slabs_used_;
    slabs_used_ += kSlabBytes;
    if (slabs_used_ > warm_) {  // past the part faulted in at construction: this slab's pages in one call
      populate(slab, kSlabBytes);
      warm_ = slabs_used_;
    }
    bump_[c] = slab;
    bump_end_[c] = slab + kSlabBytes;
  }
  // The class's current slab is carved from its start, and its never-used memory is not read: threading a
  // new slab onto the free list wrote every block of it, and each pop then read a line not touched since
  // (a cache miss per payload: texstream-bench server, misses, perf: ~3 % of the dispatcher in the pops of
  // fresh blocks, mostly the cache's shared_ptr control blocks).
  std::byte* p = bump_[c];
  bump_[c] += size;
  // The class's next block is written by the next allocation's owner (a cache entry's control block is
  // constructed at once): ask for its first lines now, with intent to write, so that the write-allocate miss
  // overlaps whatever comes in between instead of stalling the constructor.
  if (bump_[c] != bump_end_[c]) {
    for (uint64_t o = 0; o < std::min<uint64_t>(size, kPrefetchBytes); o += kLineBytes) {
      __builtin_prefetch(bump_[c] + o, 1, 3);
    }
  }
  return p;
}

void SmallPayloadPool::free(std::byte* p, uint64_t bytes) {
  TS_ASSERT(serves(bytes) && owns(p), "freeing memory the small payload pool did not hand out");
  const uint32_t c = class_of(bytes);
  std::lock_guard lock(mutex_);
  auto* n = reinterpret_cast<FreeNode*>(p);
  n->next = free_[c];
  free_[c] = n;
  in_use_ -= kMinClass << c;
}

bool SmallPayloadPool::warm_step() {
  uint64_t from = 0, to = 0;
  {
    std::lock_guard lock(mutex_);
    if (warm_ >= prefault_bytes()) return false;
    from = warm_;
    to = std::min(prefault_bytes(), from + kWarmStepBytes);
    warm_ = to;  // claimed: allocate() no longer faults these slabs in itself
  }
  populate(base_ + from, to - from);
  return to < prefault_bytes();
}

uint64_t SmallPayloadPool::bytes_warm() const {
  std::lock_guard lock(mutex_);
  return warm_;
}

uint64_t SmallPayloadPool::slab_bytes() const {
  std::lock_guard lock(mutex_);
  return slabs_used_;
}

uint64_t SmallPayloadPool::bytes_in_use() const {
  std::lock_guard lock(mutex_);
  return in_use_;
}

}  // namespace texstream::server
