#pragma once
// stream.fade_ms: a texture's newly resident finer level (or its first level) fades in over a fixed span of
// path time instead of popping in. The rule works on the texture table's entries (shared_structs.h TextureGpu):
// colour.y is the level the fade starts from (kNotResident: the colormap), colour.z the float bits of the fade
// left, 1 -> 0; scene.frag mixes the picture at the new level with the one at colour.y by it.
// Why a fixed span and what it costs in error: docs/design/blend.md.
//
// Fades are kept by table slot (TextureSlots), as the entries are. A slot is freed only for a texture without
// residency, whose entry was published not resident (no fade left), so a freed slot still listed here only
// leaves the list at the next advance(), setting colour.y to kNotResident as a fresh entry has it.
#include <cstdint>
#include <span>
#include <vector>

#include "texstream/render/cache/texture_index_map.hpp"
#include "texstream/render/scene/gpu_structs.hpp"

namespace texstream::render {

class MipFades {
 public:
  explicit MipFades(double fade_s) : fade_s_(fade_s) {}

  // The finest resident level of entry `t` (at table slot `slot`) changed from `before` (kNotResident: none) to
  // t.placement.y (kNotResident: evicted). Before the first advance() nothing fades: what a preload publishes
  // shows at once.
  void on_publish(uint32_t slot, gpu::TextureGpu& t, uint32_t before);
  // One frame's worth of path time over the table (by slot); call before drawing the frame.
  void advance(double dt_s, std::span<gpu::TextureGpu> table);
  size_t fading() const { return fading_.size(); }

 private:
  double fade_s_;
  bool started_ = false;
  std::vector<uint32_t> fading_;  // slots in listed_: a fade left, or one that ended since the last advance
  // The slots of fading_, so none is listed twice; sparse, as fading_ (docs/design/host_memory.md).
  TextureIndexMap listed_;
};

}  // namespace texstream::render
