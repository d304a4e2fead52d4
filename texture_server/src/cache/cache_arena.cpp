#include "texstream/server/cache/cache_arena.hpp"

#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <bit>

#include "texstream/common/contract.hpp"

namespace texstream::server {

namespace {

constexpr uint8_t kNoBlock = 0xff;
// The background pre-fault works in steps of this many bytes and checks for shutdown between them: 2 MiB is
// ~8 ms of faults on this machine, so a server that exits while warming waits at most that long.
constexpr uint64_t kWarmStep = 2ull << 20;

}  // namespace

uint64_t CacheArena::block_bytes(uint64_t bytes) { return std::bit_ceil(std::max<uint64_t>(bytes, kMinBlock)); }

CacheArena::CacheArena(uint64_t capacity, ArenaPrefault prefault, std::function<bool()> then_warm)
    : free_(kMaxOrders), then_warm_(std::move(then_warm)) {
  capacity_ = capacity / kMinBlock * kMinBlock;
  if (capacity_ == 0) return;
  void* p = ::mmap(nullptr, capacity_, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
  if (p == MAP_FAILED) {
    // No address space for the budget: an empty arena; the cache then keeps payloads on the heap.
    capacity_ = 0;
    return;
  }
  base_ = static_cast<std::byte*>(p);
  mapped_ = capacity_;
  // Transparent huge pages stay off: on this machine populating 256 MiB of them took 12.7 s against 1.03 s of
  // 4 KiB pages (the kernel compacts memory to find them).
  ::madvise(base_, mapped_, MADV_NOHUGEPAGE);
  const uint64_t blocks = capacity_ / kMinBlock;
  order_of_.assign(blocks, kNoBlock);
  // The capacity as a sum of aligned powers of two, largest first: each is a top block that never merges
  // with what lies past the end (its buddy would extend beyond the capacity).
  uint64_t index = 0;
  while (index < blocks) {
    const uint32_t order = static_cast<uint32_t>(std::bit_width(blocks - index) - 1);
    push_free(index, std::min(order, kMaxOrders - 1));
    index += uint64_t{1} << std::min(order, kMaxOrders - 1);
  }
  if (prefault == ArenaPrefault::kNow) {
    prefault_range(0, capacity_);
    warm_then();
  } else if (prefault == ArenaPrefault::kBackground) {
    warmer_ = std::thread([this] { warm_in_background(); });
  }
}

CacheArena::~CacheArena() {
  stop_.store(true, std::memory_order_relaxed);  // relaxed: the join below orders everything after it
  if (warmer_.joinable()) warmer_.join();
  if (base_) ::munmap(base_, mapped_);
}

void CacheArena::prefault_range(uint64_t from, uint64_t to) {
  // MADV_POPULATE_WRITE (Linux 5.14) faults the range in writable without touching its bytes; older kernels
  // get one written byte per page. Either way this is the only place the arena's pages are first touched.
  if (::madvise(base_ + from, to - from, MADV_POPULATE_WRITE) != 0) {
    const uint64_t page = static_cast<uint64_t>(::sysconf(_SC_PAGESIZE));
    for (uint64_t o = from; o < to; o += page) {
      reinterpret_cast<volatile char*>(base_)[o] = reinterpret_cast<volatile char*>(base_)[o];
    }
  }
  warm_.fetch_add(to - from, std::memory_order_relaxed);  // relaxed: a progress gauge
}

void CacheArena::warm_in_background() {
  // Low priority: faulting the arena in should not take CPU from the renderer or the server's own workers
  // (seed 002 §3.3); a payload written before its pages are warm just faults them itself. Nice 10, not
  // SCHED_IDLE: on a loaded machine a SCHED_IDLE thread can wait seconds for the CPU, and a process dies only
  // once every thread has run its exit — a SIGKILLed server was told dead 0.3-1 s late that way (and the
  // thread holds the mmap lock inside madvise while it waits, stalling the other threads' mmap/munmap).
  ::setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), 10);
  for (uint64_t from = 0; from < capacity_ && !stop_.load(std::memory_order_relaxed); from += kWarmStep) {
    prefault_range(from, std::min(capacity_, from + kWarmStep));
  }
  warm_then();
}

void CacheArena::warm_then() {
  while (then_warm_ && !stop_.load(std::memory_order_relaxed) && then_warm_()) {
  }
}

void CacheArena::wait_warm() {
  if (warmer_.joinable()) warmer_.join();
}

uint32_t CacheArena::order_for(uint64_t bytes) const {
  return static_cast<uint32_t>(std::countr_zero(block_bytes(bytes) / kMinBlock));
}

void CacheArena::push_free(uint64_t index, uint32_t order) {
  order_of_[index] = static_cast<uint8_t>(order) | kFreeBit;
  free_[order].insert(index);
}

void CacheArena::remove_free(uint64_t index, uint32_t order) {
  free_[order].erase(index);
  order_of_[index] = kNoBlock;
}

std::byte* CacheArena::allocate(uint64_t bytes) {
  TS_ASSERT(bytes > 0, "allocating 0 bytes from the cache arena");
  if (bytes > capacity_) return nullptr;
  const uint32_t want = order_for(bytes);
  if (want >= kMaxOrders) return nullptr;
  std::lock_guard lock(mutex_);
  uint32_t order = want;
  while (order < kMaxOrders && free_[order].empty()) ++order;
  if (order == kMaxOrders) return nullptr;
  const uint64_t index = *free_[order].begin();
  remove_free(index, order);
  // Split down to the wanted order; the upper halves become free buddies.
  while (order > want) {
    --order;
    push_free(index + (uint64_t{1} << order), order);
  }
  order_of_[index] = static_cast<uint8_t>(want);
  in_use_ += kMinBlock << want;
  return base_ + index * kMinBlock;
}

void CacheArena::free(std::byte* block, uint64_t bytes) {
  TS_ASSERT(owns(block), "freeing memory the cache arena does not own");
  std::lock_guard lock(mutex_);
  uint64_t index = index_of(block);
  uint32_t order = order_for(bytes);
  TS_ASSERT(order_of_[index] == order, "cache arena block %llu freed with order %u, allocated with %u",
            static_cast<unsigned long long>(index), order, static_cast<unsigned>(order_of_[index]));
  in_use_ -= kMinBlock << order;
  order_of_[index] = kNoBlock;
  const uint64_t blocks = capacity_ / kMinBlock;
  // Merge with the buddy while it is free and of the same order.
  while (order + 1 < kMaxOrders) {
    const uint64_t buddy = index ^ (uint64_t{1} << order);
    if (buddy >= blocks || order_of_[buddy] != (static_cast<uint8_t>(order) | kFreeBit)) break;
    remove_free(buddy, order);
    index = std::min(index, buddy);
    ++order;
  }
  push_free(index, order);
}

uint64_t CacheArena::bytes_in_use() const {
  std::lock_guard lock(mutex_);
  return in_use_;
}

}  // namespace texstream::server
