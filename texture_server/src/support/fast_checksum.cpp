#include "texstream/server/support/fast_checksum.hpp"

#include "texstream/protocol/checksum.hpp"

namespace texstream::server {

#if defined(__x86_64__) || defined(__i386__)
namespace {

using ChecksumFn = uint64_t (*)(const void*, size_t);

// The widest XXH3 build this CPU runs, chosen once.
ChecksumFn pick_checksum() {
  if (__builtin_cpu_supports("avx512f")) return payload_checksum_avx512;
  if (__builtin_cpu_supports("avx2")) return payload_checksum_avx2;
  return payload_checksum;
}

}  // namespace
#endif

uint64_t fast_payload_checksum(const void* data, size_t bytes) {
  // x86 with AVX-512 or AVX2: that build of XXH3; anything else: the library's (same values).
#if defined(__x86_64__) || defined(__i386__)
  static const ChecksumFn checksum = pick_checksum();
  return checksum(data, bytes);
#else
  return payload_checksum(data, bytes);
#endif
}

}  // namespace texstream::server
