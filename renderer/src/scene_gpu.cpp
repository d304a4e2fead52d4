#include "texstream/render/scene_gpu.hpp"

#include <algorithm>
#include <vector>

#include "texstream/render/broad_phase.hpp"
#include "texstream/render/one_shot.hpp"
#include "texstream/render/scene_passes.hpp"
#include "texstream/render/scene_data.hpp"
#include "texstream/render/vulkan_context.hpp"

namespace texstream::render {

Result<SceneGpu> SceneGpu::create(const VulkanContext& ctx, const SceneData& scene) {
  SceneGpu g;
  const auto& md = scene.meshes;
  g.mesh_count = static_cast<uint32_t>(md.meshes.size());
  g.compact_capacity = g.mesh_count;
  const VkDeviceSize n = std::max<VkDeviceSize>(g.mesh_count, 1);  // zero-sized buffers are invalid
  constexpr VkBufferUsageFlags kDst = VK_BUFFER_USAGE_TRANSFER_DST_BIT;

  auto make = [&](GpuBuffer& out, VkDeviceSize size, VkBufferUsageFlags usage, MemoryUse use) -> Status {
    auto b = GpuBuffer::create(ctx, size, usage, use);
    if (!b) return b.error();
    out = std::move(*b);
    return ok_status();
  };
  const VkDeviceSize vbytes = std::max<VkDeviceSize>(md.vertices.size() * sizeof(scene::Vertex), 4);
  const VkDeviceSize ibytes = std::max<VkDeviceSize>(md.indices.size() * sizeof(uint32_t), 4);
  TS_TRY(make(g.vertices, vbytes, VK_BUFFER_USAGE_VERTEX_BUFFER_BIT | kDst, MemoryUse::kDeviceLocal));
  TS_TRY(make(g.indices, ibytes, VK_BUFFER_USAGE_INDEX_BUFFER_BIT | kDst, MemoryUse::kDeviceLocal));
  TS_TRY(make(g.meshes, n * sizeof(gpu::MeshGpu), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, MemoryUse::kHostVisible));
  // Also a storage buffer: compact.comp reads the frame's mesh ids from it.
  TS_TRY(make(g.indirect, n * sizeof(VkDrawIndexedIndirectCommand),
              VK_BUFFER_USAGE_INDIRECT_BUFFER_BIT | VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, MemoryUse::kHostVisible));
  TS_TRY(make(g.mesh_meta, n * sizeof(gpu::MeshMeta), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | kDst,
              MemoryUse::kDeviceLocal));
  const VkDeviceSize list_bytes = sizeof(gpu::CompactListHeader) + n * sizeof(gpu::CompactEntry);
  TS_TRY(make(g.compacted, list_bytes,
              VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | kDst,
              MemoryUse::kDeviceLocal));
  // Written by compact.comp (COMPACT_TO_HOST): only the header and the used prefix, only when a streaming cycle
  // starts.
  TS_TRY(make(g.readback, list_bytes, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | kDst, MemoryUse::kHostVisible));
  TS_TRY(make(g.frame_uniforms, sizeof(gpu::FrameUniforms), VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT,
              MemoryUse::kHostVisible));

  TS_TRY(upload_to_buffer(ctx, g.vertices, 0, std::as_bytes(std::span(md.vertices))));
  TS_TRY(upload_to_buffer(ctx, g.indices, 0, std::as_bytes(std::span(md.indices))));
  // The sparse metadata starts "no fragment yet": mip = kNoMip (atomicMin identity), weight = 0.
  std::vector<gpu::MeshMeta> empty(n, gpu::MeshMeta{gpu::kNoMip, 0});
  TS_TRY(upload_to_buffer(ctx, g.mesh_meta, 0, std::as_bytes(std::span(empty))));
  std::fill_n(g.meshes.as<gpu::MeshGpu>(), n, gpu::MeshGpu{0, 0, 0, 0});
  for (uint32_t i = 0; i < g.mesh_count; ++i) g.meshes.as<gpu::MeshGpu>()[i].texture_id = md.meshes[i].texture_id;
  return g;
}

void SceneGpu::write_draws(const SceneData& scene, std::span<const uint32_t> visible,
                           const std::array<double, 3>& camera, const ViewportSplit& split, FrameRecording& rec) {
  const size_t main_end = std::min<size_t>(split.main_end, visible.size());
  const size_t wide_begin = std::min<size_t>(split.wide_begin, main_end);
  // Draws written before each boundary = the boundary in draw positions (write_draws skips empty meshes).
  const uint32_t before_wide = write_draws(scene, visible.first(wide_begin), camera);
  auto* draws = indirect.as<VkDrawIndexedIndirectCommand>();
  const uint32_t both = write_draws_at(scene, visible.subspan(wide_begin, main_end - wide_begin), camera,
                                       draws + before_wide);
  const uint32_t wide_only = write_draws_at(scene, visible.subspan(main_end), camera, draws + before_wide + both);
  rec.wide_first = before_wide;
  rec.main_count = before_wide + both;
  rec.draw_count = before_wide + both + wide_only;
}

uint32_t SceneGpu::write_draws(const SceneData& scene, std::span<const uint32_t> visible,
                               const std::array<double, 3>& camera) {
  return write_draws_at(scene, visible, camera, indirect.as<VkDrawIndexedIndirectCommand>());
}

uint32_t SceneGpu::write_draws_at(const SceneData& scene, std::span<const uint32_t> visible,
                                  const std::array<double, 3>& camera, VkDrawIndexedIndirectCommand* draws) {
  auto* mesh_out = meshes.as<gpu::MeshGpu>();
  uint32_t count = 0;
  for (uint32_t id : visible) {
    const scene::MeshRecord& m = scene.meshes.meshes[id];
    if (m.index_count == 0) continue;
    gpu::MeshGpu& g = mesh_out[id];
    g.offset_x = static_cast<float>(m.origin[0] - camera[0]);
    g.offset_y = static_cast<float>(m.origin[1] - camera[1]);
    g.offset_z = static_cast<float>(m.origin[2] - camera[2]);
    draws[count++] = VkDrawIndexedIndirectCommand{m.index_count, 1, m.first_index,
                                                  static_cast<int32_t>(m.first_vertex), id};
  }
  return count;
}

}  // namespace texstream::render
