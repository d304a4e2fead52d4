#pragma once
// The scene's GPU buffers: one vertex and one index buffer for every mesh, the per-mesh camera-relative
// offsets and indirect draws written each frame, the visibility metadata (sparse per mesh, then compacted) and
// the frame uniforms.
//
// Geometry follows the view, not the scene: the vertex and index buffers are allocated at the scene's size
// (each mesh keeps its meshes.bin offsets, so draws address it as before) but a mesh's data reaches them only
// when the broad phase first returns it (make_resident), copied in that frame's command buffer before its
// draws (record_uploads; on unified memory written in place by make_resident): a frame draws every mesh it
// needs, complete, and start-up uploads nothing. Its
// metadata entry is set to "no fragment" the same way, and its gpu::MeshGpu entry is written with its draw.
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/render/gpu_buffer.hpp"
#include "texstream/render/gpu_structs.hpp"

namespace texstream::render {

class VulkanContext;
struct FrameRecording;
struct ViewportSplit;
struct SceneData;

struct SceneGpuStats {
  uint64_t meshes_resident = 0;  // meshes whose geometry is on the GPU
  uint64_t meshes_uploaded = 0;  // of those, made resident by the last make_resident call
  uint64_t bytes_uploaded = 0;   // geometry and metadata bytes copied, all frames
};

struct SceneGpu {
  // `always_stage`: copy geometry through staging even on unified memory (the discrete-GPU path, for tests).
  static Result<SceneGpu> create(const VulkanContext& ctx, const SceneData& scene, bool always_stage = false);

  // Makes every mesh of `ids` drawable. A mesh seen for the first time is checked (SceneData::check_mesh: the
  // error names the file and the mesh, and nothing of it is queued), queued for record_uploads() (vertices,
  // indices, metadata reset), and its texture id is appended to `new_textures` (may be null).
  Status make_resident(const SceneData& scene, std::span<const uint32_t> ids, std::vector<uint32_t>* new_textures);
  // Records the queued copies and the barrier that makes them visible to the draws and to compact.comp, in the
  // command buffer that draws them, before ScenePasses::record. The staging buffer is reused: the submission
  // that carried the previous call must have completed (the renderer and ViewRenderer wait for each).
  Status record_uploads(const SceneData& scene, VkCommandBuffer cmd);

  // For each mesh in `visible`: its offset = origin - camera, subtracted in double and only then rounded to
  // float (no jitter at map coordinates), its texture id, and one VkDrawIndexedIndirectCommand with
  // firstInstance = mesh id. Every mesh must have been made resident. Returns the number of draws written.
  uint32_t write_draws(const SceneData& scene, std::span<const uint32_t> visible, const std::array<double, 3>& camera);
  // The same for a list reordered by BroadPhase::split_by_viewport; fills the draw ranges of `rec` (draw_count,
  // main_count, wide_first), which account for meshes without indices (never drawn).
  void write_draws(const SceneData& scene, std::span<const uint32_t> visible, const std::array<double, 3>& camera,
                   const ViewportSplit& split, FrameRecording& rec);

  bool is_resident(uint32_t mesh) const { return (resident_[mesh >> 6] >> (mesh & 63)) & 1u; }
  const SceneGpuStats& stats() const { return stats_; }

  uint32_t mesh_count = 0;
  uint32_t compact_capacity = 0;  // entries of the compacted list (= mesh count: every mesh fits)
  GpuBuffer vertices;             // scene::Vertex, device-local (host-visible too on unified memory), filled
                                  // per mesh on first use
  GpuBuffer indices;              // uint32, relative to each mesh's first vertex, the same way
  GpuBuffer meshes;               // gpu::MeshGpu[mesh_count], host-visible, written for each draw
  GpuBuffer indirect;             // VkDrawIndexedIndirectCommand[mesh_count], host-visible
  GpuBuffer mesh_meta;            // gpu::MeshMeta[mesh_count], device-local, set on first use, reset by compact.comp
  GpuBuffer compacted;            // gpu::CompactListHeader + gpu::CompactEntry[capacity], device-local
  GpuBuffer readback;             // same layout, host-visible: header + used prefix, written only when a
                                  // streaming cycle starts (compact.comp, COMPACT_TO_HOST)
  GpuBuffer frame_uniforms;       // gpu::FrameUniforms, host-visible

 private:
  uint32_t write_draws_at(const SceneData& scene, std::span<const uint32_t> visible,
                          const std::array<double, 3>& camera, VkDrawIndexedIndirectCommand* draws);

  const VulkanContext* ctx_ = nullptr;
  bool in_place_ = false;           // unified memory: make_resident writes the buffers, nothing is queued
  std::vector<uint64_t> resident_;  // one bit per mesh
  std::vector<uint32_t> queued_;    // checked, marked resident, not yet recorded
  std::vector<uint32_t> fresh_;     // make_resident's scratch: the call's meshes not resident before
  GpuBuffer staging_;               // host-visible, grown to the largest frame's uploads
  SceneGpuStats stats_;
};

}  // namespace texstream::render
