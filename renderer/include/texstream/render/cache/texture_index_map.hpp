#pragma once
// A hash map from texture id to a 32-bit value, for per-texture state that only textures in view, resident or
// in flight have (ResidencyTable, MipFades): its size follows the entries, not the scene's texture count
// (docs/design/host_memory.md). common's OpenTable (open addressing, backward-shift deletion, grown at half
// full, never shrunk: its size is the peak number of entries), keyed by texture id + 1. Not thread-safe.
#include <cstddef>
#include <cstdint>

#include "texstream/common/contract.hpp"
#include "texstream/common/ids.hpp"
#include "texstream/common/open_table.hpp"

namespace texstream::render {

class TextureIndexMap {
 public:
  static constexpr uint32_t kAbsent = UINT32_MAX;

  // Room for `expected_entries` without growing.
  explicit TextureIndexMap(size_t expected_entries = 0) : table_(expected_entries, 16) {}

  // The value of `texture`, or kAbsent.
  uint32_t find(TextureId texture) const {
    const Slot* s = table_.find(texture.value + 1);
    return s ? s->value : kAbsent;
  }
  bool contains(TextureId texture) const { return find(texture) != kAbsent; }

  // Adds `texture`, which must not be in the map.
  void insert(TextureId texture, uint32_t value) {
    TS_ASSERT(texture.value != UINT32_MAX, "texture id %u has no key", texture.value);
    table_.insert(Slot{texture.value + 1, value});
  }

  // Removes `texture`; false when it was not in the map.
  bool erase(TextureId texture) { return table_.erase(texture.value + 1); }

  size_t size() const { return table_.size(); }
  size_t slot_count() const { return table_.capacity(); }

 private:
  struct Slot {
    uint32_t key = 0;  // texture id + 1; 0: empty
    uint32_t value = 0;
  };
  struct Used {
    bool operator()(const Slot& s) const { return s.key != 0; }
  };
  OpenTable<Slot, Used, IdHash> table_;
};

}  // namespace texstream::render
