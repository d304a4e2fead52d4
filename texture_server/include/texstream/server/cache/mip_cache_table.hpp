#pragma once
// MipCache's index: an open-addressing hash table (linear probing, backward-shift deletion) from MipKey to
// the entry, with what a hit needs — payload pointer, size, checksum, the policy's node — inline in one
// 64-byte slot. A hit is one probe into one cache line in the common case; std::unordered_map walked a
// bucket and a separate node, then the CachedMip behind the shared_ptr (texstream-bench server, perf:
// the cache's metadata was 36 % of a hit's server time, mostly cache misses on those hops).
//
// The table itself is open_mip_table.hpp's. Not thread-safe: MipCache holds its lock around every call.
// Erasing moves later entries of the probe run back one slot, so pointers to entries are valid only until the
// next insert or erase.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <utility>

#include "texstream/server/cache/mip_key.hpp"
#include "texstream/server/cache/open_mip_table.hpp"

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

struct MipCacheSlotUsed {
  bool operator()(const MipCacheSlot& s) const { return s.mip != nullptr; }
};

class MipCacheTable {
 public:
  // Room for `expected_entries` without growing (the table grows at half full); at least kInitialSlots.
  explicit MipCacheTable(size_t expected_entries = 0) : table_(expected_entries, kInitialSlots) {}

  // The entry of `key`, or nullptr.
  MipCacheSlot* find(MipKey key) { return table_.find(key); }
  const MipCacheSlot* find(MipKey key) const { return table_.find(key); }

  // Starts loading the slot where find(key) begins into the CPU cache (a hint: no effect on the contents).
  void prefetch(MipKey key) const { table_.prefetch(key); }

  // Adds an entry for a key that is not in the table (the caller found none); `slot.mip` must be non-null.
  // Returns it (valid until the next insert or erase).
  MipCacheSlot* insert(MipCacheSlot slot) { return table_.insert(std::move(slot)); }

  // Removes the entry of `key` if there is one; its payload reference is moved to `out` (freed by the
  // caller after its lock is released). False if the key was not there.
  bool erase(MipKey key, std::shared_ptr<const CachedMip>& out) {
    MipCacheSlot* found = find(key);
    if (found == nullptr) return false;
    erase(found, out);
    return true;
  }
  // The same for an entry find() returned (no second lookup).
  void erase(MipCacheSlot* entry, std::shared_ptr<const CachedMip>& out) {
    out = std::move(entry->mip);
    table_.erase(entry);
  }

  size_t size() const { return table_.size(); }

 private:
  // A small table for a small cache; doubles as it fills.
  static constexpr size_t kInitialSlots = 64;

  OpenMipTable<MipCacheSlot, MipCacheSlotUsed> table_;
};

}  // namespace texstream::server
