#pragma once
// Payload checksum of a staging slot: XXH3-64 (fast enough to hash every mip on both sides).
#include <cstddef>
#include <cstdint>

namespace texstream {
uint64_t payload_checksum(const void* data, size_t bytes);
}  // namespace texstream
