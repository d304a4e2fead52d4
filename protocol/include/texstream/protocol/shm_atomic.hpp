#pragma once
// The only atomics allowed in the shared segment: lock-free always (so address-free, usable across
// processes, and immune to a peer dying mid-operation). iceoryx_platform/atomic.hpp does the same check.
#include <atomic>
#include <cstdint>

namespace texstream {

template <class T>
struct ShmAtomic {
  static_assert(std::atomic<T>::is_always_lock_free, "only always-lock-free atomics may live in shared memory");
  static_assert(sizeof(std::atomic<T>) == sizeof(T), "atomic must have the layout of its value");
  std::atomic<T> v;
};

static_assert(sizeof(ShmAtomic<uint64_t>) == 8 && alignof(ShmAtomic<uint64_t>) == 8);
static_assert(sizeof(ShmAtomic<uint32_t>) == 4 && alignof(ShmAtomic<uint32_t>) == 4);

}  // namespace texstream
