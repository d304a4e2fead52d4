#pragma once
// The scene's GPU buffers: one vertex and one index buffer for every mesh, the per-mesh camera-relative
// offsets and indirect draws written each frame, the visibility metadata (sparse per mesh, then compacted) and
// the frame uniforms.
//
// Few draws (seed 001): indices are stored absolute (each mesh's first vertex added at upload) and every vertex
// carries its mesh's id (vertex_mesh), so one indirect draw covers any run of meshes whose indices lie next to
// each other in meshes.bin. write_draws lists each pass's meshes in id order (meshes.bin keeps neighbouring
// meshes' indices together) and merges such runs:
// on the default city a view's ~650 meshes become ~70 draws. A CPU rasterizer (lavapipe) pays a fixed cost per
// draw, large next to a mesh of a few triangles; a GPU's multi-draw indirect gains less but loses nothing. A
// mesh that instances another's ranges (same vertices and indices, another origin) is drawn with every other
// instance of those ranges in the pass: one draw of instanceCount = k whose instances read their mesh ids from
// the instances buffer (firstInstance - 1 is where the draw's run starts); any other sharing of ranges is
// refused by make_resident.
//
// Geometry follows the view, not the scene: the vertex and index buffers are allocated at the scene's size
// (each mesh keeps its meshes.bin offsets) but a mesh's data reaches them only
// when the broad phase first returns it (make_resident), copied in that frame's command buffer before its
// draws (record_uploads; on unified memory written in place by make_resident): a frame draws every mesh it
// needs, complete, and start-up uploads nothing. Its
// metadata entry is set to "no fragment" the same way, and its gpu::MeshGpu entry is written with its draw.
#include <algorithm>
#include <array>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/render/scene/gpu_structs.hpp"
#include "texstream/render/vulkan/gpu_buffer.hpp"
#include "texstream/render/vulkan/zeroed_array.hpp"

namespace texstream::render {

class VulkanContext;
struct FrameRecording;
struct ViewportSplit;
struct SceneData;
class TextureSlots;

struct SceneGpuStats {
  uint64_t meshes_resident = 0;  // meshes whose geometry is on the GPU
  uint64_t meshes_uploaded = 0;  // of those, made resident by the last make_resident call
  uint64_t bytes_uploaded = 0;   // geometry and metadata bytes copied, all frames
};

class SceneGpu {
 public:
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

  // For a list split by BroadPhase::split_by_viewport: for each mesh, its offset = origin - camera, subtracted
  // in double and only then rounded to float (no jitter at map coordinates), its texture id and its texture's
  // slot (slots.use(): kept by this frame, handed out when the texture has none), and its id in `drawn` (once);
  // then two draw lists, the main pass's (meshes touching the viewport) and the wide pass's
  // (meshes outside it): each list's meshes in id order, one VkDrawIndexedIndirectCommand per run of
  // adjacent index ranges. Fills the draw ranges of `rec` (draw_count, main_count, wide_first = main_count),
  // rec.mesh_count and the per-pass mesh counts; meshes without indices are never drawn. A pass draws its
  // meshes in id order, whatever order the broad phase returned them in, so which of
  // two coplanar meshes owns a pixel does not depend on the spatial index. Every mesh must have been made
  // resident.
  void write_draws(const SceneData& scene, std::span<const uint32_t> visible, const std::array<double, 3>& camera,
                   const ViewportSplit& split, TextureSlots& slots, FrameRecording& rec);

  bool is_resident(uint32_t mesh) const { return (resident_[mesh >> 6] >> (mesh & 63)) & 1u; }
  // A resident mesh that shares its owner's vertex and index ranges (instancing): drawn alone.
  bool is_instanced(uint32_t mesh) const { return (instanced_[mesh >> 6] >> (mesh & 63)) & 1u; }
  const SceneGpuStats& stats() const { return stats_; }

  uint32_t mesh_count() const { return mesh_count_; }
  uint32_t compact_capacity() const { return compact_capacity_; }
  // The frame's constants, written by the frame plan before the passes are recorded.
  void set_frame_uniforms(const gpu::FrameUniforms& uniforms) { *frame_uniforms_.as<gpu::FrameUniforms>() = uniforms; }
  // The GPU's count of the last read-back compacted list (may exceed compact_capacity()) and its used prefix;
  // valid after a submission whose FrameRecording had read_back_list set has completed.
  uint32_t read_back_count() const { return readback_.as<gpu::CompactListHeader>()->count; }
  std::span<const gpu::CompactEntry> read_back_entries() const {
    const auto* entries =
        reinterpret_cast<const gpu::CompactEntry*>(readback_.bytes().data() + sizeof(gpu::CompactListHeader));
    return {entries, std::min(read_back_count(), compact_capacity_)};
  }

  // The buffers, for the passes that bind them (ScenePasses) and for tests; only SceneGpu writes them, except
  // the passes' own view fields of the frame uniforms.
  const GpuBuffer& vertices() const { return vertices_; }
  const GpuBuffer& vertex_mesh() const { return vertex_mesh_; }
  const GpuBuffer& indices() const { return indices_; }
  const GpuBuffer& meshes() const { return meshes_; }
  const GpuBuffer& indirect() const { return indirect_; }
  const GpuBuffer& drawn() const { return drawn_; }
  const GpuBuffer& instances() const { return instances_; }
  const GpuBuffer& mesh_meta() const { return mesh_meta_; }
  const GpuBuffer& compacted() const { return compacted_; }
  const GpuBuffer& readback() const { return readback_; }
  const GpuBuffer& frame_uniforms() const { return frame_uniforms_; }

 private:
  // One pass's list: the meshes' merged draws from draw position `draw_at`, the instanced meshes' ids from
  // instances_[instance_at] on (advanced past them); returns {meshes, draws}.
  std::pair<uint32_t, uint32_t> write_list(const SceneData& scene, std::span<const uint32_t> ids, uint32_t draw_at,
                                           uint32_t& instance_at);
  // Appends mesh `id` (indices [first_index, + index_count)) to draws[0, count): extends the open run if it
  // continues it, else starts a draw.
  void emit_draw(uint32_t first_index, uint32_t index_count, VkDrawIndexedIndirectCommand* draws, uint32_t& count,
                 bool& open) const;

  uint32_t mesh_count_ = 0;
  uint32_t compact_capacity_ = 0;  // entries of the compacted list (= mesh count: every mesh fits)
  GpuBuffer vertices_;             // scene::Vertex, device-local (host-visible too on unified memory), filled
                                   // per mesh on first use
  GpuBuffer vertex_mesh_;          // uint32 per vertex: the id of the mesh the vertex belongs to, the same way
  GpuBuffer indices_;              // uint32, absolute (meshes.bin's index + the mesh's first vertex), the same way
  GpuBuffer meshes_;               // gpu::MeshGpu[mesh_count], host-visible, written for each draw
  GpuBuffer indirect_;             // VkDrawIndexedIndirectCommand[2 * mesh_count], host-visible: the main pass's
                                   // list, then the wide pass's (at most one draw per mesh each)
  GpuBuffer drawn_;                // uint32[mesh_count], host-visible: the frame's drawn meshes (compact.comp)
  GpuBuffer instances_;            // uint32[mesh_count], host-visible: the ids of the instanced draws' meshes,
                                   // each draw's run of them from firstInstance - 1 (scene.vert)
  GpuBuffer mesh_meta_;            // gpu::MeshMeta[mesh_count], device-local, set on first use, reset by compact.comp
  GpuBuffer compacted_;            // gpu::CompactListHeader + gpu::CompactEntry[capacity], device-local
  GpuBuffer readback_;             // same layout, host-visible: header + used prefix, written only when a
                                   // streaming cycle starts (compact.comp, COMPACT_TO_HOST)
  GpuBuffer frame_uniforms_;       // gpu::FrameUniforms, host-visible
  const VulkanContext* ctx_ = nullptr;
  bool in_place_ = false;                         // unified memory: make_resident writes the buffers, nothing is queued
  std::vector<uint64_t> resident_;                // one bit per mesh
  std::vector<uint32_t> queued_;                  // checked, marked resident, not yet recorded
  std::vector<uint32_t> fresh_;                   // make_resident's scratch: the call's meshes not resident before
  std::vector<uint64_t> in_list_;                 // write_list's scratch: one bit per mesh, all clear between calls
  std::vector<std::array<uint32_t, 3>> grouped_;  // write_list's scratch: (first index, index count, id) of instances
  std::vector<uint64_t> instanced_;       // one bit per mesh: its ranges are another resident mesh's (instancing)
  std::vector<uint64_t> vertex_claimed_;  // one bit per vertex / index of meshes.bin: owned by a resident mesh
  std::vector<uint64_t> index_claimed_;
  ZeroedArray<uint32_t> range_owner_;  // at an owned index range's first index: the owner's id + 1 (0: none)
  GpuBuffer staging_;                  // host-visible, grown to the largest frame's uploads
  SceneGpuStats stats_;
};

}  // namespace texstream::render
