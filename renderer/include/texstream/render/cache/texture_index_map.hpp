#pragma once
// A hash map from texture id to a 32-bit value, for per-texture state that only textures in view, resident or
// in flight have (ResidencyTable, MipFades): its size follows the entries, not the scene's texture count
// (docs/design/host_memory.md). Open addressing with linear probing and backward-shift deletion, like the
// server's OpenMipTable: no node per entry, no tombstones. Grows at half full; never shrinks (its size is the
// peak number of entries). Not thread-safe.
#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "texstream/common/contract.hpp"
#include "texstream/common/ids.hpp"

namespace texstream::render {

class TextureIndexMap {
 public:
  static constexpr uint32_t kAbsent = UINT32_MAX;

  // Room for `expected_entries` without growing.
  explicit TextureIndexMap(size_t expected_entries = 0)
      : slots_(std::bit_ceil(std::max<size_t>(16, 2 * expected_entries))), mask_(slots_.size() - 1) {}

  // The value of `texture`, or kAbsent.
  uint32_t find(TextureId texture) const {
    const uint32_t key = texture.value + 1;
    for (size_t i = home(key);; i = (i + 1) & mask_) {
      const Slot& s = slots_[i];
      if (s.key == key) return s.value;
      if (s.key == 0) return kAbsent;
    }
  }
  bool contains(TextureId texture) const { return find(texture) != kAbsent; }

  // Adds `texture`, which must not be in the map.
  void insert(TextureId texture, uint32_t value) {
    TS_ASSERT(texture.value != UINT32_MAX, "texture id %u has no key", texture.value);
    // Half full at most: linear probing then averages ~1.5 probes for a hit and ~2.5 for a miss.
    if ((size_ + 1) * 2 > slots_.size()) grow();
    place(Slot{texture.value + 1, value});
    ++size_;
  }

  // Removes `texture`; false when it was not in the map.
  bool erase(TextureId texture) {
    const uint32_t key = texture.value + 1;
    size_t hole = home(key);
    while (slots_[hole].key != key) {
      if (slots_[hole].key == 0) return false;
      hole = (hole + 1) & mask_;
    }
    // Backward shift: an entry later in the run moves into the hole unless its home lies cyclically in
    // (hole, j]; then the hole is not on its probe path and it must stay.
    for (size_t j = (hole + 1) & mask_; slots_[j].key != 0; j = (j + 1) & mask_) {
      const size_t h = home(slots_[j].key);
      const bool stays = hole <= j ? (hole < h && h <= j) : (hole < h || h <= j);
      if (stays) continue;
      slots_[hole] = slots_[j];
      hole = j;
    }
    slots_[hole] = Slot{};
    --size_;
    return true;
  }

  size_t size() const { return size_; }
  size_t slot_count() const { return slots_.size(); }

 private:
  struct Slot {
    uint32_t key = 0;  // texture id + 1; 0: empty
    uint32_t value = 0;
  };
  // Fibonacci hashing: texture ids come in runs (a mesh's, a tile's), which must not fill one probe run.
  size_t home(uint32_t key) const { return static_cast<size_t>((uint64_t{key} * 0x9E3779B97F4A7C15ull) >> 32) & mask_; }
  void place(Slot slot) {
    size_t i = home(slot.key);
    while (slots_[i].key != 0) i = (i + 1) & mask_;
    slots_[i] = slot;
  }
  void grow() {
    std::vector<Slot> old(slots_.size() * 2);
    old.swap(slots_);
    mask_ = slots_.size() - 1;
    for (const Slot& s : old)
      if (s.key != 0) place(s);
  }

  std::vector<Slot> slots_;
  size_t mask_;
  size_t size_ = 0;
};

}  // namespace texstream::render
