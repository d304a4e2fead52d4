#pragma once
// The payload checksum (protocol/checksum.hpp: XXH3-64) computed with AVX-512 or AVX2 where the CPU has
// it. The value is the same as payload_checksum()'s — XXH3 defines one result for every vector width — only
// the speed differs: the shared libxxhash is built for SSE2 and hashed ~12 GB/s on this machine, the AVX2
// code ~45 GB/s (32 KiB buffers). On a miss the server hashes every byte it delivers, so at 12 GB/s the hash
// was a sixth of a miss's server time (texstream-bench server, perf of the loader alone); with AVX2 it was
// still the dispatcher's largest user-space symbol in the miss stream (~9 %). The AVX-512 build (this
// machine's EPYC has AVX-512F) hashed 64 KiB buffers at 48-83 GB/s against AVX2's ~38 GB/s, and took the
// loader's time for the bench's miss set down ~2-3 % (paired runs of a loader-only harness).
#include <cstddef>
#include <cstdint>

namespace texstream::server {

// payload_checksum(data, bytes), faster where AVX-512 or AVX2 is available (checked once, at the first call).
uint64_t fast_payload_checksum(const void* data, size_t bytes);

#if defined(__x86_64__) || defined(__i386__)
// The builds fast_payload_checksum() chooses from (fast_checksum_avx2.cpp, fast_checksum_avx512.cpp); only to
// be called where __builtin_cpu_supports() says the CPU has the extension. Declared for the tests, which
// check each build the CPU runs against payload_checksum().
uint64_t payload_checksum_avx2(const void* data, size_t bytes);
uint64_t payload_checksum_avx512(const void* data, size_t bytes);
#endif

}  // namespace texstream::server
