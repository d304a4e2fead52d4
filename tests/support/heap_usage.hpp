#pragma once
// Heap growth in tests that prove a structure costs nothing per texture not in view (docs/design/host_memory.md).
// glibc: its books, the arena's chunks in use plus the blocks it mmap'd (a large dense vector is one of those, so
// counting the arena alone would miss exactly what these tests look for). Under ASan or TSan malloc is the
// sanitizer's, which mallinfo2 does not see: there, the sanitizer's own count of bytes the program holds.
// Header-only; "../support/heap_usage.hpp".
#include <malloc.h>

#include <cstddef>

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
// Exported by libasan and libtsan (sanitizer/allocator_interface.h, which GCC 12 does not install).
extern "C" size_t __sanitizer_get_current_allocated_bytes();
#endif

namespace texstream::test {

// Bytes the process's malloc holds now.
inline size_t heap_bytes() {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  return __sanitizer_get_current_allocated_bytes();
#else
  const struct mallinfo2 m = mallinfo2();
  return m.uordblks + m.hblkhd;
#endif
}

}  // namespace texstream::test
