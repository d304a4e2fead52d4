#include "texstream/server/small_payload_pool.hpp"

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
  if (free_[c] == nullptr) {
    if (slabs_used_ + kSlabBytes > capacity_) return nullptr;
    std::byte* slab = base_ + slabs_used_;
    slabs_used_ += kSlabBytes;
    if (slabs_used_ > warm_) {  // past the part faulted in at construction: this slab's pages in one call
      populate(slab, kSlabBytes);
      warm_ = slabs_used_;
    }
    // Threaded back to front so that allocation walks the slab from its start.
    for (uint64_t o = kSlabBytes; o >= size; o -= size) {
      auto* n = reinterpret_cast<FreeNode*>(slab + o - size);
      n->next = free_[c];
      free_[c] = n;
    }
  }
  FreeNode* n = free_[c];
  free_[c] = n->next;
  in_use_ += size;
  return reinterpret_cast<std::byte*>(n);
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

uint64_t SmallPayloadPool::slab_bytes() const {
  std::lock_guard lock(mutex_);
  return slabs_used_;
}

uint64_t SmallPayloadPool::bytes_in_use() const {
  std::lock_guard lock(mutex_);
  return in_use_;
}

}  // namespace texstream::server
