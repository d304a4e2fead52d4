#pragma once
// A map from MipKey to a small value, for the dispatcher's per-request bookkeeping (RequestScheduler's
// pending requests), on open_mip_table.hpp's table (the RAM cache's index uses the same one): the value inline
// in its slot.
// std::unordered_map allocated a node per request, freed it at the pop, and walked bucket → node on each
// lookup: in texstream-bench server's hit phase (perf, dispatcher thread) the scheduler's add/pop/find/erase
// were ~19 % of the dispatcher's samples, most of it in the hash table; ~8 % with this map. Full
// `texstream-bench server --quick`, 8 alternating pairs (with the bench's own fixes of the same change):
// hit_vs_memcpy median 0.516 -> 0.551 (7 of 8 pairs up); misses unchanged within the noise.
//
// Not thread-safe. Pointers to values are valid only until the next insert or erase (erasing moves later
// entries of the probe run back one slot; inserting may grow the table).
#include <cstddef>
#include <utility>
#include <vector>

#include "texstream/server/cache/mip_key.hpp"
#include "texstream/server/cache/open_mip_table.hpp"

namespace texstream::server {

template <class V>
class FlatMipMap {
 public:
  FlatMipMap() : table_(0, kInitialSlots) {}

  // The value of `key`, or nullptr.
  V* find(MipKey key) {
    Slot* s = table_.find(key);
    return s == nullptr ? nullptr : &s->value;
  }
  const V* find(MipKey key) const { return const_cast<FlatMipMap*>(this)->find(key); }

  // Adds `key` (which must not be in the map: the caller looked first). Returns its value.
  V* insert(MipKey key, V value) { return &table_.insert(Slot{key, true, std::move(value)})->value; }

  // Removes `key` if present; false if it was not there.
  bool erase(MipKey key) { return table_.erase(key); }

  // Removes every entry for which keep(key, value) is false; each removed value is passed to gone(value)
  // first. O(capacity).
  template <class Keep, class Gone>
  void erase_if_not(Keep&& keep, Gone&& gone) {
    // Backward shift may move an entry from later in the table (or, at the wrap-around, from its start) into
    // a slot already scanned, so the removed keys are gathered first and erased after the scan.
    std::vector<MipKey>& doomed = scratch_;
    doomed.clear();
    table_.for_each([&](const Slot& s) {
      if (!keep(s.key, s.value)) {
        gone(s.value);
        doomed.push_back(s.key);
      }
    });
    for (const MipKey k : doomed) table_.erase(k);
  }

  // Calls f(key, value) for every entry (in slot order, not insertion order).
  template <class F>
  void for_each(F&& f) const {
    table_.for_each([&f](const Slot& s) { f(s.key, s.value); });
  }

  size_t size() const { return table_.size(); }
  bool empty() const { return table_.empty(); }

 private:
  struct Slot {
    MipKey key;
    bool used = false;
    V value{};
  };
  struct SlotUsed {
    bool operator()(const Slot& s) const { return s.used; }
  };
  // 64 pending requests before the first growth; the table grows to the largest queue seen and stays.
  static constexpr size_t kInitialSlots = 128;

  OpenMipTable<Slot, SlotUsed> table_;
  std::vector<MipKey> scratch_;  // erase_if_not's removed keys: no allocation per call once warm
};

}  // namespace texstream::server
