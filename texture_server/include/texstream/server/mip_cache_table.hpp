#pragma once
// MipCache's index: an open-addressing hash table (linear probing, backward-shift deletion) from MipKey to
// the entry, with what a hit needs — payload pointer, size, checksum, the policy's node — inline in one
// 64-byte slot. A hit is one probe into one cache line in the common case; std::unordered_map walked a
// bucket and a separate node, then the CachedMip behind the shared_ptr (texstream-bench server, perf:
// the cache's metadata was 36 % of a hit's server time, mostly cache misses on those hops).
//
// Not thread-safe: MipCache holds its lock around every call. Erasing moves later entries of the probe run
// back one slot, so pointers to entries are valid only until the next insert or erase.
#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "texstream/server/mip_key.hpp"

namespace texstream::server {

struct CachedMip;
struct PolicyNode;

// One cached mip as the index sees it. `mip` owns the payload (and is the pin count's reference); `data`,
// `size` and `checksum` are copies of its fields, so a hit does not dereference it. Empty slot: mip null.
struct alignas(64) MipCacheSlot {
  MipKey key;
  const std::byte* data = nullptr;
  uint64_t size = 0;
  uint64_t checksum = 0;
  PolicyNode* node = nullptr;
  std::shared_ptr<const CachedMip> mip;
  // Read ahead of any request (MipLoader's coarse-tail read) and not handed out yet: its first hit is the
  // delivery its storage read paid for (read amplification counts it then, never if it is evicted unused).
  bool prefetched = false;
};
static_assert(sizeof(MipCacheSlot) == 64, "a hit reads one cache line of the index");

class MipCacheTable {
 public:
  // Room for `expected_entries` without growing (the table grows at half full); at least kInitialSlots.
  // The slots are written here (value-initialised), so their pages are faulted in now, not by inserts.
  explicit MipCacheTable(size_t expected_entries = 0)
      : slots_(std::bit_ceil(std::max(kInitialSlots, 2 * expected_entries))), mask_(slots_.size() - 1) {}

  // The entry of `key`, or nullptr.
  MipCacheSlot* find(MipKey key) {
    for (size_t i = home(key);; i = (i + 1) & mask_) {
      MipCacheSlot& s = slots_[i];
      if (!s.mip) return nullptr;
      if (s.key == key) return &s;
    }
  }
  const MipCacheSlot* find(MipKey key) const { return const_cast<MipCacheTable*>(this)->find(key); }

  // Starts loading the slot where find(key) begins into the CPU cache (a hint: no effect on the contents).
  void prefetch(MipKey key) const { __builtin_prefetch(&slots_[home(key)], 0, 3); }

  // Adds an entry for a key that is not in the table (the caller found none); `slot.mip` must be non-null.
  // Returns it (valid until the next insert or erase).
  MipCacheSlot* insert(MipCacheSlot slot) {
    // Grown at half full: linear probing then averages ~1.5 probes for a hit and ~2.5 for a miss.
    if ((size_ + 1) * 2 > slots_.size()) grow();
    MipCacheSlot* s = place(std::move(slot));
    ++size_;
    return s;
  }

  // Removes the entry of `key` if there is one; its payload reference is moved to `out` (freed by the
  // caller after its lock is released). False if the key was not there.
  bool erase(MipKey key, std::shared_ptr<const CachedMip>& out) {
    MipCacheSlot* found = find(key);
    if (found == nullptr) return false;
    size_t hole = static_cast<size_t>(found - slots_.data());
    out = std::move(found->mip);
    // Backward shift: an entry later in the run moves into the hole unless its home lies cyclically in
    // (hole, j] — then the hole is not on its probe path and it must stay.
    for (size_t j = (hole + 1) & mask_; slots_[j].mip; j = (j + 1) & mask_) {
      const size_t h = home(slots_[j].key);
      const bool stays = hole <= j ? (hole < h && h <= j) : (hole < h || h <= j);
      if (stays) continue;
      slots_[hole] = std::move(slots_[j]);
      hole = j;
    }
    slots_[hole] = MipCacheSlot{};
    --size_;
    return true;
  }

  size_t size() const { return size_; }

 private:
  // A small table for a small cache; doubles as it fills.
  static constexpr size_t kInitialSlots = 64;

  size_t home(MipKey key) const { return MipKeyHash{}(key) & mask_; }

  MipCacheSlot* place(MipCacheSlot&& slot) {
    size_t i = home(slot.key);
    while (slots_[i].mip) i = (i + 1) & mask_;
    slots_[i] = std::move(slot);
    return &slots_[i];
  }

  void grow() {
    std::vector<MipCacheSlot> old(slots_.size() * 2);
    old.swap(slots_);
    mask_ = slots_.size() - 1;
    for (MipCacheSlot& s : old) {
      if (s.mip) place(std::move(s));
    }
  }

  std::vector<MipCacheSlot> slots_;
  size_t mask_;
  size_t size_ = 0;
};

}  // namespace texstream::server
