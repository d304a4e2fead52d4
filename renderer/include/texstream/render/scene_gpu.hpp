#pragma once
// The scene's GPU buffers: one vertex and one index buffer for every mesh, the per-mesh camera-relative
// offsets and indirect draws written each frame, the visibility metadata (sparse per mesh, then compacted) and
// the frame uniforms.
#include <array>
#include <cstdint>
#include <span>

#include "texstream/common/result.hpp"
#include "texstream/render/gpu_buffer.hpp"
#include "texstream/render/gpu_structs.hpp"

namespace texstream::render {

class VulkanContext;
struct FrameRecording;
struct ViewportSplit;
struct SceneData;

struct SceneGpu {
  static Result<SceneGpu> create(const VulkanContext& ctx, const SceneData& scene);

  // For each mesh in `visible`: its offset = origin - camera, subtracted in double and only then rounded to
  // float (no jitter at map coordinates), and one VkDrawIndexedIndirectCommand with firstInstance = mesh id.
  // Returns the number of draws written.
  uint32_t write_draws(const SceneData& scene, std::span<const uint32_t> visible, const std::array<double, 3>& camera);
  // The same for a list reordered by BroadPhase::split_by_viewport; fills the draw ranges of `rec` (draw_count,
  // main_count, wide_first), which account for meshes without indices (never drawn).
  void write_draws(const SceneData& scene, std::span<const uint32_t> visible, const std::array<double, 3>& camera,
                   const ViewportSplit& split, FrameRecording& rec);

  uint32_t mesh_count = 0;
  uint32_t compact_capacity = 0;  // entries of the compacted list (= mesh count: every mesh fits)
  GpuBuffer vertices;             // scene::Vertex, device-local
  GpuBuffer indices;              // uint32, relative to each mesh's first vertex, device-local
  GpuBuffer meshes;               // gpu::MeshGpu[mesh_count], host-visible
  GpuBuffer indirect;             // VkDrawIndexedIndirectCommand[mesh_count], host-visible
  GpuBuffer mesh_meta;            // gpu::MeshMeta[mesh_count], device-local, reset by compact.comp
  GpuBuffer compacted;            // gpu::CompactListHeader + gpu::CompactEntry[capacity], device-local
  GpuBuffer readback;             // same layout, host-visible: header + used prefix, written only when a
                                  // streaming cycle starts (compact.comp, COMPACT_TO_HOST)
  GpuBuffer frame_uniforms;       // gpu::FrameUniforms, host-visible

 private:
  uint32_t write_draws_at(const SceneData& scene, std::span<const uint32_t> visible,
                          const std::array<double, 3>& camera, VkDrawIndexedIndirectCommand* draws);
};

}  // namespace texstream::render
