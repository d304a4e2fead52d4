#pragma once
// Strong ids: a TextureId is not a SlotIndex is not a MipLevel (filament Handle.h style). Each wraps one
// fixed-width integer, is trivially copyable, and converts to its raw value only through .value.
#include <compare>
#include <cstdint>
#include <functional>

namespace texstream {

template <class Tag, class Rep>
struct StrongId {
  Rep value{};
  constexpr StrongId() = default;
  constexpr explicit StrongId(Rep v) : value(v) {}
  constexpr auto operator<=>(const StrongId&) const = default;
};

struct TextureIdTag {};
struct MipLevelTag {};
struct SlotIndexTag {};
struct GenerationTag {};
struct MeshIdTag {};

using TextureId = StrongId<TextureIdTag, uint32_t>;
using MipLevel = StrongId<MipLevelTag, uint32_t>;  // 0 = full resolution
using SlotIndex = StrongId<SlotIndexTag, uint32_t>;
using Generation = StrongId<GenerationTag, uint64_t>;  // streaming cycle number, ever increasing
using MeshId = StrongId<MeshIdTag, uint32_t>;

}  // namespace texstream

template <class Tag, class Rep>
struct std::hash<texstream::StrongId<Tag, Rep>> {
  size_t operator()(const texstream::StrongId<Tag, Rep>& id) const noexcept { return std::hash<Rep>{}(id.value); }
};
