#pragma once
// (texture, mip) packed into one integer: the key of the RAM cache and of the request scheduler.
#include <cstdint>

#include "texstream/common/ids.hpp"

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
  size_t operator()(MipKey k) const noexcept {
    // splitmix64 finaliser: texture ids are dense and mips tiny, so the raw value hashes badly into buckets.
    uint64_t x = k.value + 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return static_cast<size_t>(x ^ (x >> 31));
  }
};

}  // namespace texstream::server
