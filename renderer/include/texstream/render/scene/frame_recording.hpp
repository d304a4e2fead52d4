#pragma once
// What one frame's scene passes draw: the draw lists SceneGpu::write_draws fills and ScenePasses::record
// replays (see frame/scene_passes.hpp for the passes). Its own header so the scene and the passes that
// draw it do not include each other.
#include <cstdint>

#include "texstream/render/scene/gpu_structs.hpp"

namespace texstream::render {

// All draws of the list (the default of FrameRecording::main_count).
inline constexpr uint32_t kAllDraws = 0xffffffffu;

struct FrameRecording {
  uint32_t draw_count = 0;   // draws written by SceneGpu::write_draws (each covers a run of meshes)
  uint32_t mesh_count = 0;   // meshes those draws cover (SceneGpu::drawn; compact.comp visits them)
  uint32_t main_meshes = 0;  // of those, drawn by the main pass / by the wide pass (statistics)
  uint32_t wide_meshes = 0;
  // Draws [0, main_count) are the main pass's (meshes touching the viewport's frustum), draws
  // [wide_first, draw_count) the wide pass's (meshes entirely outside it). SceneGpu::write_draws writes them
  // as two lists (wide_first = main_count). The defaults draw the whole list in both passes.
  uint32_t main_count = kAllDraws;
  uint32_t wide_first = 0;
  gpu::PassConstants main{};
  gpu::PassConstants wide{};
  bool read_back_list = false;  // compact into SceneGpu::readback (host-visible) instead of SceneGpu::compacted
  bool feedback = true;         // metadata writes, wide pass, compaction (false: only the picture)
};

}  // namespace texstream::render
