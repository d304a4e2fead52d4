#pragma once
// The per-frame GPU constants of the scene passes, computed from a camera and the configuration: the main and
// wide passes' push constants and the frame uniforms. One definition, used by the one frame plan
// (frame_plan.hpp) of the frame loop and the offline ViewRenderer (tests, benchmark).
#include <array>
#include <cstdint>

#include "texstream/common/config.hpp"
#include "texstream/render/scene/camera.hpp"
#include "texstream/render/scene/gpu_structs.hpp"

namespace texstream::render {

gpu::PassConstants main_pass_constants(const Camera& cam);
// The wide off-screen pass at wide_height px: its lod offset and per-fragment weight (seed 000 §3.2).
gpu::PassConstants wide_pass_constants(const Camera& cam, double fov_y_deg, double wide_fov_y_deg, uint32_t height,
                                       uint32_t wide_height);
// Everything but FrameUniforms.view and the kFlagFeedback bit (ScenePasses::record sets those).
// `cache_layer_extents`: the layer side of each cache plane (0 past the last).
gpu::FrameUniforms frame_uniforms(const Camera& cam, const Config& cfg, uint32_t mesh_count, uint32_t compact_capacity,
                                  const std::array<uint32_t, 4>& cache_layer_extents);

}  // namespace texstream::render
