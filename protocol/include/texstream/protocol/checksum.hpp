#pragma once
// Payload checksum of a staging slot: XXH3-64 (fast enough to hash every mip on both sides).
#include <cstddef>
#include <cstdint>

namespace texstream {
uint64_t payload_checksum(const void* data, size_t bytes);

// The texture table's fingerprint, one texture at a time in id order, starting from kTextureTableSeed: the
// renderer states it in the segment header and a server whose scene gives another one refuses to serve (the
// two read different scenes). Over each texture's width, height, mip count and format.
inline constexpr uint64_t kTextureTableSeed = 0x7465787461626c65ull;  // "textable"
uint64_t texture_table_step(uint64_t fingerprint, uint32_t width, uint32_t height, uint32_t mip_count,
                            uint32_t format);
}  // namespace texstream
