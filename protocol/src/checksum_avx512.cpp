// Compiled with -mavx512f (CMakeLists.txt): XXH3's AVX-512 code, inlined. Called only after the CPU was checked
// (checksum.cpp). Like checksum_avx2.cpp, it holds nothing but xxHash's own static functions, so no
// AVX-512 copy of an inline C++ function shared with other translation units can be kept by the linker.
// GCC 12's own avx512fintrin.h trips -Wuninitialized and -Wmaybe-uninitialized (its _mm512_undefined_*
// helpers, GCC bug 105593): a warning about the compiler's header, not this code; this file holds nothing else.
// GCC only: clang (the fuzz build) has no -Wmaybe-uninitialized and its own header does not warn.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#endif
#define XXH_INLINE_ALL
#include <xxhash.h>

#include <cstddef>
#include <cstdint>

namespace texstream {

uint64_t payload_checksum_avx512(const void* data, size_t bytes) { return XXH3_64bits(data, bytes); }

}  // namespace texstream
