// Compiled with -mavx2 (CMakeLists.txt): XXH3's AVX2 code, inlined. Called only after the CPU was checked
// (checksum.cpp). Holds nothing but xxHash's own static functions: no inline C++ function that another
// translation unit also instantiates may be compiled with AVX2 here (the linker could keep this copy for all).
#define XXH_INLINE_ALL
#include <xxhash.h>

#include <cstddef>
#include <cstdint>

namespace texstream {

uint64_t payload_checksum_avx2(const void* data, size_t bytes) { return XXH3_64bits(data, bytes); }

}  // namespace texstream
