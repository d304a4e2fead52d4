#include "texstream/server/dispatch/slot_pool.hpp"

#include "texstream/common/contract.hpp"

namespace texstream::server {

SlotPool::SlotPool(uint32_t slot_count) : owner_(slot_count, Owner::kServerFree) {
  free_.reserve(slot_count);
  // Pushed in reverse so that slot 0 is taken first (easier to read in logs and tests).
  for (uint32_t i = slot_count; i > 0; --i) free_.push_back(i - 1);
}

std::optional<uint32_t> SlotPool::acquire() {
  if (free_.empty()) return std::nullopt;
  const uint32_t slot = free_.back();
  free_.pop_back();
  TS_ASSERT(owner_[slot] == Owner::kServerFree, "slot %u on the free list is not free", slot);
  owner_[slot] = Owner::kLoading;
  return slot;
}

void SlotPool::release_unused(uint32_t slot) {
  TS_ASSERT(slot < owner_.size() && owner_[slot] == Owner::kLoading, "slot %u was not loading", slot);
  owner_[slot] = Owner::kServerFree;
  free_.push_back(slot);
}

void SlotPool::hand_to_renderer(uint32_t slot) {
  TS_ASSERT(slot < owner_.size() && owner_[slot] == Owner::kLoading, "slot %u was not loading", slot);
  owner_[slot] = Owner::kRenderer;
}

bool SlotPool::release_from_renderer(uint32_t slot) {
  if (slot >= owner_.size() || owner_[slot] != Owner::kRenderer) return false;
  owner_[slot] = Owner::kServerFree;
  free_.push_back(slot);
  return true;
}

}  // namespace texstream::server
