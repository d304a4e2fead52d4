#pragma once
// The open-addressing hash table behind the per-id indexes that must cost nothing for an id not in them: the
// server's per-mip tables (MipCacheTable: the RAM cache's entries; FlatMipMap: the dispatcher's pending
// requests) and the renderer's per-texture streaming states and mip ledger (TextureStates, MipUseLedger:
// docs/design/host_memory.md). Linear probing, backward-shift deletion, the whole entry inline in its slot, no
// allocation per entry. std::unordered_map allocated a node per entry and walked bucket → node on every lookup;
// in texstream-bench server (perf) those hops were most of the cache's metadata cost and most of the scheduler's.
//
// `Slot` is the entry type: it has a `key` member, a value-initialised Slot is empty, and `Used{}(slot)` says
// whether a slot holds an entry; `Hash{}(key)` mixes the key into every bit (splitmix64_finalize). Not
// thread-safe. Erasing moves later entries of the probe run back one slot and inserting may grow the table, so
// pointers to slots are valid only until the next insert or erase. Memory: the slots, a power of two at least
// twice the entries at their peak (it never shrinks; clear() keeps the slots too).
#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace texstream {

// The splitmix64 finaliser: ids are dense (and a mip key's low bits tiny), so the raw value hashes badly into
// the low bits a power-of-two table uses.
constexpr uint64_t splitmix64_finalize(uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

// The hash of a dense 32-bit id (a texture's): its splitmix64 finaliser.
struct IdHash {
  size_t operator()(uint32_t id) const { return static_cast<size_t>(splitmix64_finalize(id)); }
};

template <class Slot, class Used, class Hash>
class OpenTable {
 public:
  using Key = decltype(Slot::key);

  // Room for `expected_entries` without growing (the table grows at half full); at least `min_slots`. The
  // slots are value-initialised here, so their pages are faulted in now, not by inserts.
  explicit OpenTable(size_t expected_entries = 0, size_t min_slots = 64)
      : slots_(std::bit_ceil(std::max(min_slots, 2 * expected_entries))), mask_(slots_.size() - 1) {}

  // The slot of `key`, or nullptr.
  Slot* find(Key key) {
    for (size_t i = home(key);; i = (i + 1) & mask_) {
      Slot& s = slots_[i];
      if (!Used{}(s)) return nullptr;
      if (s.key == key) return &s;
    }
  }
  const Slot* find(Key key) const { return const_cast<OpenTable*>(this)->find(key); }

  // Starts loading the slot where find(key) begins into the CPU cache (a hint: no effect on the contents).
  void prefetch(Key key) const { __builtin_prefetch(&slots_[home(key)], 0, 3); }

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
  bool erase(Key key) {
    Slot* found = find(key);
    if (found == nullptr) return false;
    erase(found);
    return true;
  }

  // Removes every entry; the slots stay allocated.
  void clear() {
    std::fill(slots_.begin(), slots_.end(), Slot{});
    size_ = 0;
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
  // Slots allocated (each sizeof(Slot) bytes): the table's memory.
  size_t capacity() const { return slots_.size(); }

 private:
  size_t home(Key key) const { return Hash{}(key)&mask_; }

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

}  // namespace texstream
