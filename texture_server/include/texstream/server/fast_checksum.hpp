#pragma once
// The payload checksum (protocol/checksum.hpp: XXH3-64) computed with AVX2 where the CPU has it. The value is
// the same as payload_checksum()'s — XXH3 defines one result for every vector width — only the speed
// differs: the shared libxxhash is built for SSE2 and hashed ~12 GB/s on this machine, the AVX2 code ~45 GB/s
// (32 KiB buffers). On a miss the server hashes every byte it delivers, so at 12 GB/s the hash was a sixth
// of a miss's server time (texstream-bench server, perf of the loader alone).
#include <cstddef>
#include <cstdint>

namespace texstream::server {

// payload_checksum(data, bytes), faster where AVX2 is available (checked once, at the first call).
uint64_t fast_payload_checksum(const void* data, size_t bytes);

}  // namespace texstream::server
