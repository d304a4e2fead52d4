#pragma once
// Payload checksum of a staging slot: XXH3-64 (fast enough to hash every mip on both sides). Both processes
// call this one function; it runs the widest XXH3 build the CPU has (AVX-512, AVX2, else the library's SSE2
// one), chosen once. Every build gives the same value. Measurements: docs/design/payload_checksum.md.
#include <cstddef>
#include <cstdint>

namespace texstream {
uint64_t payload_checksum(const void* data, size_t bytes);

// The builds payload_checksum() chooses from, declared for the tests (which check each build the CPU runs).
// The vector ones only where __builtin_cpu_supports() says the CPU has the extension.
uint64_t payload_checksum_sse2(const void* data, size_t bytes);
#if defined(__x86_64__) || defined(__i386__)
uint64_t payload_checksum_avx2(const void* data, size_t bytes);
uint64_t payload_checksum_avx512(const void* data, size_t bytes);
#endif

// The texture table's fingerprint, one texture at a time in id order, starting from kTextureTableSeed: the
// renderer states it in the segment header and a server whose scene gives another one refuses to serve (the
// two read different scenes). Over each texture's width, height, mip count and format.
inline constexpr uint64_t kTextureTableSeed = 0x7465787461626c65ull;  // "textable"
uint64_t texture_table_step(uint64_t fingerprint, uint32_t width, uint32_t height, uint32_t mip_count, uint32_t format);
}  // namespace texstream
