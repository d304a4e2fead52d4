#include "texstream/protocol/checksum.hpp"

#include <xxhash.h>

namespace texstream {
uint64_t payload_checksum(const void* data, size_t bytes) { return XXH3_64bits(data, bytes); }
}  // namespace texstream
