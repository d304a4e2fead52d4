#pragma once
// Which entry ("slot") of the GPU texture table (TextureCache, gpu::TextureGpu) a texture has. The table holds
// the textures that need an entry: those drawn in the current frame (SceneGpu::write_draws writes the slot into
// each drawn mesh's gpu::MeshGpu::texture_slot) and those with cache state (TextureCache's residency), so its
// size follows the view and the cache, not the scene's texture count (docs/design/host_memory.md, item 3).
//
// Costs: 4 B per texture, the texture -> slot map, calloc'd (ZeroedArray: committed only on pages of textures
// that had a slot); 8-12 B per slot (its texture, the frame that last drew it, a place on the free list).
//
// A slot freed by release_unused() may be handed to another texture at once: the renderer submits each frame and
// waits for it before planning the next (RenderStack::submit), and a frame's meshes name only slots of textures
// it draws, which release_unused() keeps. Frame-thread only.
#include <cstdint>
#include <vector>

#include "texstream/common/contract.hpp"
#include "texstream/render/vulkan/zeroed_array.hpp"

namespace texstream::render {

class TextureSlots {
 public:
  static constexpr uint32_t kNone = UINT32_MAX;

  explicit TextureSlots(size_t texture_count) : slot_of_(texture_count) {}

  // The texture's slot, or kNone.
  uint32_t find(uint32_t texture) const { return slot_of_[texture] - 1; }  // 0 (none) wraps to kNone
  // The texture's slot, handed out (and listed in take_fresh()) when it has none.
  uint32_t acquire(uint32_t texture) {
    const uint32_t s = slot_of_[texture];
    return s != 0 ? s - 1 : assign(texture);
  }
  // acquire(), and the slot is kept by the current frame (begin_frame()): SceneGpu::write_draws, per drawn mesh.
  uint32_t use(uint32_t texture) {
    const uint32_t s = acquire(texture);
    drawn_in_[s] = frame_;
    return s;
  }
  // A new frame: the slots its draws use() are kept until the next release_unused() after the next begin_frame().
  void begin_frame() { ++frame_; }
  // Frees the slot of every texture not drawn in the current frame for which keep(texture) is false.
  template <class Keep>
  void release_unused(Keep&& keep) {
    for (uint32_t s = 0; s < texture_of_.size(); ++s) {
      const uint32_t t = texture_of_[s];
      if (t == kNone || drawn_in_[s] == frame_ || keep(t)) continue;
      slot_of_[t] = 0;
      texture_of_[s] = kNone;
      free_.push_back(s);
      ++released_;
    }
  }
  // The textures given a slot since the last call (their table entries are to be written), in order.
  std::vector<uint32_t> take_fresh() {
    std::vector<uint32_t> out;
    out.swap(fresh_);
    return out;
  }

  // Slots ever handed out: the table must hold this many entries.
  uint32_t high_water() const { return static_cast<uint32_t>(texture_of_.size()); }
  uint32_t in_use() const { return high_water() - static_cast<uint32_t>(free_.size()); }
  uint32_t texture_of(uint32_t slot) const { return texture_of_[slot]; }
  uint64_t released() const { return released_; }

 private:
  uint32_t assign(uint32_t texture) {
    uint32_t s;
    if (!free_.empty()) {
      s = free_.back();
      free_.pop_back();
    } else {
      TS_ASSERT(texture_of_.size() < kNone - 1, "texture slots exhausted");
      s = static_cast<uint32_t>(texture_of_.size());
      texture_of_.push_back(kNone);
      drawn_in_.push_back(0);
    }
    texture_of_[s] = texture;
    drawn_in_[s] = 0;  // not drawn yet (frame_ starts at 1 with the first begin_frame)
    slot_of_[texture] = s + 1;
    fresh_.push_back(texture);
    return s;
  }

  ZeroedArray<uint32_t> slot_of_;     // per texture: slot + 1, 0 = none
  std::vector<uint32_t> texture_of_;  // per slot: its texture, kNone = free
  std::vector<uint32_t> drawn_in_;    // per slot: the frame that last drew it (use())
  std::vector<uint32_t> free_;
  std::vector<uint32_t> fresh_;
  uint32_t frame_ = 0;
  uint64_t released_ = 0;
};

}  // namespace texstream::render
