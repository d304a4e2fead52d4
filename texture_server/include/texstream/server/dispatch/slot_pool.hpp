#pragma once
// Who owns each staging slot (segment_layout.hpp): the server at start; the renderer after a kOk completion
// names the slot; the server again after the renderer's kReleaseSlot. A slot handed to a worker is "loading".
// The free list is a stack sized once at start, so taking and returning a slot never allocates.
// Dispatcher thread only.
#include <cstdint>
#include <optional>
#include <vector>

namespace texstream::server {

class SlotPool {
 public:
  enum class Owner : uint8_t { kServerFree, kLoading, kRenderer };

  explicit SlotPool(uint32_t slot_count);

  // A free slot for a load (owner becomes kLoading), or nullopt when every slot is loading or with the renderer.
  std::optional<uint32_t> acquire();
  // A load failed or was dropped: the slot is free again. Must be kLoading.
  void release_unused(uint32_t slot);
  // A kOk completion naming the slot is published: the renderer owns it now. Must be kLoading.
  void hand_to_renderer(uint32_t slot);
  // The renderer's kReleaseSlot. Returns false (and changes nothing) unless slot < count and the renderer
  // owns it: a record from the ring is untrusted.
  bool release_from_renderer(uint32_t slot);

  uint32_t free_count() const { return static_cast<uint32_t>(free_.size()); }
  uint32_t count() const { return static_cast<uint32_t>(owner_.size()); }
  Owner owner(uint32_t slot) const { return owner_.at(slot); }

 private:
  std::vector<Owner> owner_;
  std::vector<uint32_t> free_;
};

}  // namespace texstream::server
