#include "texstream/protocol/checksum.hpp"

#include <xxhash.h>

namespace texstream {
uint64_t payload_checksum(const void* data, size_t bytes) { return XXH3_64bits(data, bytes); }

uint64_t texture_table_step(uint64_t fingerprint, uint32_t width, uint32_t height, uint32_t mip_count,
                            uint32_t format) {
  const uint32_t fields[4] = {width, height, mip_count, format};
  return XXH3_64bits_withSeed(fields, sizeof fields, fingerprint);
}
}  // namespace texstream
