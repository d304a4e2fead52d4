#pragma once
// Heap growth in tests that prove a structure costs nothing per texture not in view (docs/design/host_memory.md):
// glibc's books, the arena's chunks in use plus the blocks it mmap'd (a large dense vector is one of those, so
// counting the arena alone would miss exactly what these tests look for). Header-only; "../support/heap_usage.hpp".
#include <malloc.h>

#include <cstddef>

namespace texstream::test {

// Under ASan or TSan malloc is the sanitizer's and mallinfo2 sees none of its blocks: the tests skip there.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
inline constexpr bool kHeapMeasured = false;
#else
inline constexpr bool kHeapMeasured = true;
#endif

// Bytes the process's malloc holds now.
inline size_t heap_bytes() {
  const struct mallinfo2 m = mallinfo2();
  return m.uordblks + m.hblkhd;
}

}  // namespace texstream::test
