#pragma once
// Fixed-size blocks for the nodes of the cache's bookkeeping (the eviction policies' list nodes), carved from
// chunks that are allocated — and written, so their pages are faulted in — up front by reserve(), and
// recycled through a free list afterwards.
//
// Why: every insert into a fresh cache allocated a policy node from malloc, and a fresh heap grows page by
// page (texstream-bench server, misses, perf of the dispatcher: the heap's growth — an mprotect and a page
// fault per 4 KiB, ~4 µs each here — was a visible share of a miss). With the nodes reserved when the cache
// is built, an insert is a free-list pop.
//
// Not thread-safe: used under the cache's lock, like the policies (eviction_policy.hpp). Memory is returned
// only when the pool is destroyed; past the reserve it grows by chunks of kChunkBlocks.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <vector>

namespace texstream::server {

class NodePool {
 public:
  // One block: a cache line, room for the policies' nodes (checked by PoolAllocator at compile time).
  static constexpr size_t kBlockBytes = 64;
  // Growth step past the reserve: 64 KiB.
  static constexpr size_t kChunkBlocks = 1024;

  NodePool() = default;
  NodePool(const NodePool&) = delete;
  NodePool& operator=(const NodePool&) = delete;

  // Makes sure `blocks` blocks can be handed out without allocating (counting those in use).
  void reserve(size_t blocks);
  void* allocate();
  void deallocate(void* p);

  size_t capacity() const { return capacity_; }  // blocks held (in use or free)
  size_t in_use() const { return in_use_; }

 private:
  struct alignas(kBlockBytes) Block {
    Block* next;  // while free
    std::byte rest[kBlockBytes - sizeof(Block*)];
  };
  void add_chunk(size_t blocks);

  std::vector<std::unique_ptr<Block[]>> chunks_;
  Block* free_ = nullptr;
  size_t capacity_ = 0;
  size_t in_use_ = 0;
};

// A standard allocator over a NodePool for node-based containers (std::list): single objects come from the
// pool, anything else (arrays) from operator new. Copies share the pool, which must outlive them.
template <class T>
class PoolAllocator {
 public:
  using value_type = T;
  explicit PoolAllocator(NodePool& pool) : pool_(&pool) {}
  template <class U>
  PoolAllocator(const PoolAllocator<U>& other) : pool_(other.pool()) {}  // NOLINT: rebinding is implicit

  T* allocate(size_t n) {
    if constexpr (sizeof(T) <= NodePool::kBlockBytes && alignof(T) <= NodePool::kBlockBytes) {
      if (n == 1) return static_cast<T*>(pool_->allocate());
    }
    return static_cast<T*>(::operator new(n * sizeof(T)));
  }
  void deallocate(T* p, size_t n) {
    if constexpr (sizeof(T) <= NodePool::kBlockBytes && alignof(T) <= NodePool::kBlockBytes) {
      if (n == 1) {
        pool_->deallocate(p);
        return;
      }
    }
    ::operator delete(p);
  }
  NodePool* pool() const { return pool_; }
  template <class U>
  bool operator==(const PoolAllocator<U>& other) const {
    return pool_ == other.pool();
  }

 private:
  NodePool* pool_;
};

}  // namespace texstream::server
