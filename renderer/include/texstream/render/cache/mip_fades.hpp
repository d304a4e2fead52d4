#pragma once
// stream.fade_ms: a texture's newly resident finer level (or its first level) fades in over a fixed span of
// path time instead of popping in. The rule works on the texture table's entries (shared_structs.h TextureGpu):
// colour.y is the level the fade starts from (kNotResident: the colormap), colour.z the float bits of the fade
// left, 1 -> 0; scene.frag mixes the picture at the new level with the one at colour.y by it.
// Why a fixed span and what it costs in error: docs/design/blend.md.
#include <cstdint>
#include <span>
#include <vector>

#include "texstream/render/scene/gpu_structs.hpp"
#include "texstream/render/vulkan/zeroed_array.hpp"

namespace texstream::render {

class MipFades {
 public:
  MipFades(double fade_s, size_t texture_count) : fade_s_(fade_s), listed_(texture_count) {}

  // The entry's finest resident level changed from `before` (kNotResident: none) to t.placement.y (kNotResident:
  // evicted). Before the first advance() nothing fades: what a preload publishes shows at once.
  void on_publish(uint32_t texture, gpu::TextureGpu& t, uint32_t before);
  // One frame's worth of path time; call before drawing the frame.
  void advance(double dt_s, std::span<gpu::TextureGpu> table);
  size_t fading() const { return fading_.size(); }

 private:
  double fade_s_;
  bool started_ = false;
  std::vector<uint32_t> fading_;  // textures with listed_ set: a fade left, or one that ended since the last advance
  ZeroedArray<uint8_t> listed_;
};

}  // namespace texstream::render
