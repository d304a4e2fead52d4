#pragma once
// The open-addressing hash table behind the server's per-mip indexes (MipCacheTable: the RAM cache's entries;
// FlatMipMap: the dispatcher's pending requests): linear probing, backward-shift deletion, the whole entry
// inline in its slot, no allocation per entry. std::unordered_map allocated a node per entry and walked bucket
// → node on every lookup; in texstream-bench server (perf) those hops were most of the cache's metadata cost
// and most of the scheduler's.
//
// `Slot` is the entry type: it has a `MipKey key` member, a value-initialised Slot is empty, and
// `Used{}(slot)` says whether a slot holds an entry. Not thread-safe. Erasing moves later entries of the
// probe run back one slot and inserting may grow the table, so pointers to slots are valid only until the
// next insert or erase.
#include <algorithm>
#include <bit>
#include <cstddef>
#include <utility>
#include <vector>

#include "texstream/server/cache/mip_key.hpp"

namespace texstream::server {

template <class Slot, class Used>
class OpenMipTable {
 public:
  // Room for `expected_entries` without growing (the table grows at half full); at least `min_slots`. The
  // slots are value-initialised here, so their pages are faulted in now, not by inserts.
  explicit OpenMipTable(size_t expected_entries = 0, size_t min_slots = 64)
      : slots_(std::bit_ceil(std::max(min_slots, 2 * expected_entries))), mask_(slots_.size() - 1) {}

  // The slot of `key`, or nullptr.
  Slot* find(MipKey key) {
    for (size_t i = home(key);; i = (i + 1) & mask_) {
      Slot& s = slots_[i];
      if (!Used{}(s)) return nullptr;
      if (s.key == key) return &s;
    }
  }
  const Slot* find(MipKey key) const { return const_cast<OpenMipTable*>(this)->find(key); }

  // Starts loading the slot where find(key) begins into the CPU cache (a hint: no effect on the contents).
  void prefetch(MipKey key) const { __builtin_prefetch(&slots_[home(key)], 0, 3); }

  // Adds an entry whose key is not in the table (the caller found none); Used{}(slot) must hold. Returns it.
  Slot* insert(Slot slot) {
    // Grown at half full: linear probing then averages ~1.5 probes for a hit and ~2.5 for a miss.
    if ((size_ + 1) * 2 > slots_.size()) grow();
    Slot* s = place(std::move(slot));
    ++size_;
    return s;
  }

  // Removes the entry in `slot` (a pointer find() returned since the last insert or erase).
  void erase(Slot* slot) {
    size_t hole = static_cast<size_t>(slot - slots_.data());
    // Backward shift: an entry later in the run moves into the hole unless its home lies cyclically in
    // (hole, j] — then the hole is not on its probe path and it must stay.
    for (size_t j = (hole + 1) & mask_; Used{}(slots_[j]); j = (j + 1) & mask_) {
      const size_t h = home(slots_[j].key);
      const bool stays = hole <= j ? (hole < h && h <= j) : (hole < h || h <= j);
      if (stays) continue;
      slots_[hole] = std::move(slots_[j]);
      hole = j;
    }
    slots_[hole] = Slot{};
    --size_;
  }
  // Removes the entry of `key`; false if there was none.
  bool erase(MipKey key) {
    Slot* found = find(key);
    if (found == nullptr) return false;
    erase(found);
    return true;
  }

  // Calls f(slot) for every entry, in slot order (not insertion order).
  template <class F>
  void for_each(F&& f) const {
    for (const Slot& s : slots_) {
      if (Used{}(s)) f(s);
    }
  }

  size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }

 private:
  size_t home(MipKey key) const { return MipKeyHash{}(key)&mask_; }

  Slot* place(Slot&& slot) {
    size_t i = home(slot.key);
    while (Used{}(slots_[i])) i = (i + 1) & mask_;
    slots_[i] = std::move(slot);
    return &slots_[i];
  }

  void grow() {
    std::vector<Slot> old(slots_.size() * 2);
    old.swap(slots_);
    mask_ = slots_.size() - 1;
    for (Slot& s : old) {
      if (Used{}(s)) place(std::move(s));
    }
  }

  std::vector<Slot> slots_;
  size_t mask_;
  size_t size_ = 0;
};

}  // namespace texstream::server
