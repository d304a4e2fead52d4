#pragma once
// (texture, mip) packed into one integer: the key of the RAM cache and of the request scheduler.
#include <cstdint>

#include "texstream/common/ids.hpp"
#include "texstream/common/open_table.hpp"

namespace texstream::server {

struct MipKey {
  uint64_t value = 0;
  constexpr MipKey() = default;
  constexpr MipKey(TextureId texture, MipLevel mip) : value((uint64_t{texture.value} << 32) | mip.value) {}
  constexpr TextureId texture() const { return TextureId(static_cast<uint32_t>(value >> 32)); }
  constexpr MipLevel mip() const { return MipLevel(static_cast<uint32_t>(value)); }
  constexpr bool operator==(const MipKey&) const = default;
};

struct MipKeyHash {
  // Texture ids are dense and mips tiny, so the raw value hashes badly into buckets (open_table.hpp).
  size_t operator()(MipKey k) const noexcept { return static_cast<size_t>(splitmix64_finalize(k.value)); }
};

}  // namespace texstream::server
