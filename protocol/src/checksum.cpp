#include "texstream/protocol/checksum.hpp"

#include <xxhash.h>

namespace texstream {

#if defined(__x86_64__) || defined(__i386__)
namespace {

using ChecksumFn = uint64_t (*)(const void*, size_t);

// The widest XXH3 build this CPU runs, chosen once. libxxhash's own XXH3_64bits_dispatch does the same but
// measured slower in texstream-bench server (docs/design/payload_checksum.md), so the builds are ours.
ChecksumFn pick_checksum() {
  if (__builtin_cpu_supports("avx512f")) return payload_checksum_avx512;
  if (__builtin_cpu_supports("avx2")) return payload_checksum_avx2;
  return payload_checksum_sse2;
}

}  // namespace
#endif

uint64_t payload_checksum_sse2(const void* data, size_t bytes) { return XXH3_64bits(data, bytes); }

uint64_t payload_checksum(const void* data, size_t bytes) {
#if defined(__x86_64__) || defined(__i386__)
  static const ChecksumFn checksum = pick_checksum();
  return checksum(data, bytes);
#else
  return XXH3_64bits(data, bytes);
#endif
}

uint64_t texture_table_step(uint64_t fingerprint, uint32_t width, uint32_t height, uint32_t mip_count,
                            uint32_t format) {
  const uint32_t fields[4] = {width, height, mip_count, format};
  return XXH3_64bits_withSeed(fields, sizeof fields, fingerprint);
}
}  // namespace texstream
