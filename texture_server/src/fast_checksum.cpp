#include "texstream/server/fast_checksum.hpp"

#include "texstream/protocol/checksum.hpp"

namespace texstream::server {

uint64_t payload_checksum_avx2(const void* data, size_t bytes);  // fast_checksum_avx2.cpp

uint64_t fast_payload_checksum(const void* data, size_t bytes) {
  // x86 with AVX2: the AVX2 build of XXH3; anything else: the library's (same values).
#if defined(__x86_64__) || defined(__i386__)
  static const bool avx2 = __builtin_cpu_supports("avx2");
  if (avx2) return payload_checksum_avx2(data, bytes);
#endif
  return payload_checksum(data, bytes);
}

}  // namespace texstream::server
