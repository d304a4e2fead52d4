#include "texstream/render/scene/scene_gpu.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cstring>
#include <limits>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "texstream/render/scene/broad_phase.hpp"
#include "texstream/render/scene/frame_recording.hpp"
#include "texstream/render/scene/scene_data.hpp"
#include "texstream/render/scene/texture_slots.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

namespace texstream::render {

namespace {

// make_resident checks this many new meshes or more on several threads (TBB), in chunks of the grain: a
// mesh's check takes about a microsecond, so below a few thousand the tasks cost more than they save.
constexpr size_t kParallelCheckMin = 4096;
constexpr size_t kParallelCheckGrain = 1024;

// The "no fragment yet" metadata entry compact.comp also resets to (atomicMin identity, zero weight).
constexpr gpu::MeshMeta kEmptyMeta{gpu::kNoMip, 0};

// Copies into one destination buffer, merged while both source and destination continue the previous one.
void add_region(std::vector<VkBufferCopy>& regions, VkDeviceSize src, VkDeviceSize dst, VkDeviceSize size) {
  if (size == 0) return;
  if (!regions.empty()) {
    VkBufferCopy& last = regions.back();
    if (last.srcOffset + last.size == src && last.dstOffset + last.size == dst) {
      last.size += size;
      return;
    }
  }
  regions.push_back(VkBufferCopy{src, dst, size});
}

// At most this many regions per vkCmdCopyBuffer. The Khronos validation layer before 1.3.290 (Debian 12 has
// 1.3.239) checks every pair of a call's regions (Vulkan-ValidationLayers issue 8224): the first frame of a
// 5.7 M-texture city (730 K meshes, a region each) did not finish in 9 minutes with the layer on.
constexpr size_t kRegionsPerCopyCall = 256;

void copy_regions(VkCommandBuffer cmd, VkBuffer src, VkBuffer dst, std::span<const VkBufferCopy> regions) {
  for (size_t at = 0; at < regions.size(); at += kRegionsPerCopyCall) {
    const size_t n = std::min(kRegionsPerCopyCall, regions.size() - at);
    vkCmdCopyBuffer(cmd, src, dst, static_cast<uint32_t>(n), regions.data() + at);
  }
}

// Unified memory (lavapipe, integrated GPUs): every host-visible, coherent memory type is device-local, so a
// host-visible buffer is as fast for the GPU as a device-local one and meshes can be written in place: one
// copy (file -> buffer) instead of three (file -> staging -> GPU copy). A discrete GPU keeps its geometry in
// device-local memory and gets it through staging copies.
bool unified_memory(const VulkanContext& ctx) {
  VkPhysicalDeviceMemoryProperties mp{};
  vkGetPhysicalDeviceMemoryProperties(ctx.physical_device(), &mp);
  constexpr VkMemoryPropertyFlags kHost = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
  bool any = false;
  for (uint32_t i = 0; i < mp.memoryTypeCount; ++i) {
    const VkMemoryPropertyFlags f = mp.memoryTypes[i].propertyFlags;
    if ((f & kHost) != kHost) continue;
    if (!(f & VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT)) return false;
    any = true;
  }
  return any;
}

// The absolute indices of mesh `m` (meshes.bin's, relative to its first vertex, plus that vertex) into `out`.
// check_mesh guarantees each is below m.vertex_count and create() that first_vertex + vertex_count fits 32 bits.
void absolute_indices(const scene::MeshRecord& m, std::span<const uint32_t> all, uint32_t* out) {
  const uint32_t* in = all.data() + m.first_index;
  for (uint32_t k = 0; k < m.index_count; ++k) out[k] = in[k] + m.first_vertex;
}

// Whether no element of [first, first + count) is marked in `bits`, and marking or clearing that range.
bool range_free(const std::vector<uint64_t>& bits, uint64_t first, uint64_t count) {
  for (uint64_t i = first; i < first + count; ++i)
    if ((bits[i >> 6] >> (i & 63)) & 1u) return false;
  return true;
}
void mark_range(std::vector<uint64_t>& bits, uint64_t first, uint64_t count, bool on) {
  for (uint64_t i = first; i < first + count; ++i) {
    const uint64_t b = uint64_t{1} << (i & 63);
    bits[i >> 6] = on ? (bits[i >> 6] | b) : (bits[i >> 6] & ~b);
  }
}

bool same_ranges(const scene::MeshRecord& a, const scene::MeshRecord& b) {
  return a.first_vertex == b.first_vertex && a.vertex_count == b.vertex_count && a.first_index == b.first_index &&
         a.index_count == b.index_count;
}

}  // namespace

Result<SceneGpu> SceneGpu::create(const VulkanContext& ctx, const SceneData& scene, bool always_stage) {
  SceneGpu g;
  g.ctx_ = &ctx;
  const auto records = scene.mesh_records();
  g.mesh_count_ = static_cast<uint32_t>(records.size());
  g.compact_capacity_ = g.mesh_count_;
  const VkDeviceSize n = std::max<VkDeviceSize>(g.mesh_count_, 1);  // zero-sized buffers are invalid
  constexpr VkBufferUsageFlags kDst = VK_BUFFER_USAGE_TRANSFER_DST_BIT;

  auto make = [&](GpuBuffer& out, VkDeviceSize size, VkBufferUsageFlags usage, MemoryUse use) -> Status {
    auto b = GpuBuffer::create(ctx, size, usage, use);
    if (!b) return b.error();
    out = std::move(*b);
    return ok_status();
  };
  // Allocated at the scene's size, filled only where meshes are used (make_resident): nothing is written here,
  // so creating them costs the same for any scene.
  // Indices are stored absolute (first vertex added) in 32 bits, so every vertex must be addressable by one.
  if (scene.vertices().size() > std::numeric_limits<uint32_t>::max())
    return make_error(ErrorCode::kCorrupt, scene.dir.string() +
                                               "/meshes.bin: " + std::to_string(scene.vertices().size()) +
                                               " vertices; at most 2^32 - 1 can be drawn with 32-bit indices");
  const VkDeviceSize vbytes = std::max<VkDeviceSize>(scene.vertices().size() * sizeof(scene::Vertex), 4);
  const VkDeviceSize vmbytes = std::max<VkDeviceSize>(scene.vertices().size() * sizeof(uint32_t), 4);
  const VkDeviceSize ibytes = std::max<VkDeviceSize>(scene.indices().size() * sizeof(uint32_t), 4);
  g.in_place_ = !always_stage && unified_memory(ctx);
  const MemoryUse geometry = g.in_place_ ? MemoryUse::kHostVisible : MemoryUse::kDeviceLocal;
  TS_TRY(make(g.vertices_, vbytes, VK_BUFFER_USAGE_VERTEX_BUFFER_BIT | kDst, geometry));
  TS_TRY(make(g.vertex_mesh_, vmbytes, VK_BUFFER_USAGE_VERTEX_BUFFER_BIT | kDst, geometry));
  TS_TRY(make(g.indices_, ibytes, VK_BUFFER_USAGE_INDEX_BUFFER_BIT | kDst, geometry));
  TS_TRY(make(g.meshes_, n * sizeof(gpu::MeshGpu), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, MemoryUse::kHostVisible));
  // Two lists (main pass, wide pass), each at most one draw per mesh.
  TS_TRY(make(g.indirect_, 2 * n * sizeof(VkDrawIndexedIndirectCommand), VK_BUFFER_USAGE_INDIRECT_BUFFER_BIT,
              MemoryUse::kHostVisible));
  TS_TRY(make(g.drawn_, n * sizeof(uint32_t), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, MemoryUse::kHostVisible));
  TS_TRY(make(g.instances_, n * sizeof(uint32_t), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, MemoryUse::kHostVisible));
  TS_TRY(make(g.mesh_meta_, n * sizeof(gpu::MeshMeta), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | kDst, geometry));
  const VkDeviceSize list_bytes = sizeof(gpu::CompactListHeader) + n * sizeof(gpu::CompactEntry);
  TS_TRY(make(g.compacted_, list_bytes, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | kDst, MemoryUse::kDeviceLocal));
  // Written by compact.comp (COMPACT_TO_HOST): only the header and the used prefix, only when a streaming cycle
  // starts.
  TS_TRY(make(g.readback_, list_bytes, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | kDst, MemoryUse::kHostRead));
  TS_TRY(
      make(g.frame_uniforms_, sizeof(gpu::FrameUniforms), VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT, MemoryUse::kHostVisible));
  g.resident_.assign((static_cast<size_t>(g.mesh_count_) + 63) / 64, 0);
  g.in_list_.assign((static_cast<size_t>(g.mesh_count_) + 63) / 64, 0);
  g.instanced_.assign((static_cast<size_t>(g.mesh_count_) + 63) / 64, 0);
  // Bits per vertex and index (10^7 of them: 1.25 MB of zeros); the owner's id only where its index range
  // starts, in zero pages from the kernel (committed only where the view's meshes lie). A word per element
  // cost ~30 ms of page faults on a 10^5-mesh first frame.
  g.vertex_claimed_.assign((scene.vertices().size() + 63) / 64, 0);
  g.index_claimed_.assign((scene.indices().size() + 63) / 64, 0);
  g.range_owner_ = ZeroedArray<uint32_t>(scene.indices().size());
  return g;
}

Status SceneGpu::make_resident(const SceneData& scene, std::span<const uint32_t> ids,
                               std::vector<uint32_t>* new_textures) {
  const auto records = scene.mesh_records();
  stats_.meshes_uploaded = 0;
  fresh_.clear();
  for (uint32_t id : ids) {
    TS_ASSERT(id < mesh_count_, "make_resident of mesh %u of %u", id, mesh_count_);
    if (is_resident(id)) continue;
    resident_[id >> 6] |= uint64_t{1} << (id & 63);  // also skips a repeated id
    fresh_.push_back(id);
  }
  if (fresh_.empty()) return ok_status();

  // The checks read the mapped file only: a view's first frame checks its meshes on every core. The first
  // failing mesh in `ids` order is reported, whatever the scheduling, and then none of them is made resident.
  std::atomic<size_t> first_bad{fresh_.size()};
  auto check = [&](size_t begin, size_t end) {
    for (size_t k = begin; k < end && k < first_bad.load(std::memory_order_relaxed); ++k) {
      if (scene.check_mesh(fresh_[k]).ok()) continue;
      // Lowers first_bad to k unless a lower index failed already (relaxed: only the final minimum matters,
      // read after the parallel_for joins).
      size_t seen = first_bad.load(std::memory_order_relaxed);
      while (k < seen && !first_bad.compare_exchange_weak(seen, k, std::memory_order_relaxed)) {
      }
      return;
    }
  };
  if (fresh_.size() < kParallelCheckMin) {
    check(0, fresh_.size());
  } else {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, fresh_.size(), kParallelCheckGrain),
                      [&](const tbb::blocked_range<size_t>& r) { check(r.begin(), r.end()); });
  }
  if (first_bad.load() < fresh_.size()) {
    for (uint32_t id : fresh_) resident_[id >> 6] &= ~(uint64_t{1} << (id & 63));
    return scene.check_mesh(fresh_[first_bad.load()]);  // the same error, built once
  }
  // Absolute indices and per-vertex mesh ids make the first mesh to use a vertex or index range its owner.
  // meshes.bin allows sharing; the sharing a city needs is instancing (the same vertices and indices at
  // another origin), and such a mesh reads its owner's absolute indices unchanged and is drawn alone, its id
  // in firstInstance (scene.vert). Any other overlap would draw wrong geometry, so it is refused here, naming
  // the mesh, before anything of the call is written: its claims are undone, none of its meshes is resident.
  for (size_t k = 0; k < fresh_.size(); ++k) {
    const uint32_t id = fresh_[k];
    const scene::MeshRecord& m = records[id];
    if (range_free(vertex_claimed_, m.first_vertex, m.vertex_count) &&
        range_free(index_claimed_, m.first_index, m.index_count)) {
      mark_range(vertex_claimed_, m.first_vertex, m.vertex_count, true);
      mark_range(index_claimed_, m.first_index, m.index_count, true);
      if (m.index_count > 0) range_owner_[m.first_index] = id + 1;
      continue;
    }
    // An empty index range has no owner to compare with; such a mesh is never drawn.
    const uint32_t owner = m.index_count > 0 ? range_owner_[m.first_index] : 0;
    if (owner != 0 && same_ranges(records[owner - 1], m)) {
      instanced_[id >> 6] |= uint64_t{1} << (id & 63);
      continue;
    }
    for (size_t j = 0; j < k; ++j) {
      const uint32_t c = fresh_[j];
      const scene::MeshRecord& r = records[c];
      if (is_instanced(c)) {  // it claimed nothing
        instanced_[c >> 6] &= ~(uint64_t{1} << (c & 63));
        continue;
      }
      mark_range(vertex_claimed_, r.first_vertex, r.vertex_count, false);
      mark_range(index_claimed_, r.first_index, r.index_count, false);
      if (r.index_count > 0) range_owner_[r.first_index] = 0;
    }
    for (uint32_t c : fresh_) resident_[c >> 6] &= ~(uint64_t{1} << (c & 63));
    return make_error(ErrorCode::kCorrupt, (scene.dir / "meshes.bin").string() + ": mesh " + std::to_string(id) +
                                               ": its vertex or index range overlaps another mesh's without being "
                                               "the same ranges (only whole-mesh instancing can share)");
  }

  for (uint32_t id : fresh_) {
    const scene::MeshRecord& m = records[id];
    if (in_place_ && is_instanced(id)) {
      mesh_meta_.as<gpu::MeshMeta>()[id] = kEmptyMeta;  // its geometry is its owner's
      stats_.bytes_uploaded += sizeof(gpu::MeshMeta);
    } else if (in_place_) {
      // No submission reads a mesh before it is resident, so its ranges can be written now; the next
      // vkQueueSubmit makes the host writes visible to the GPU.
      const size_t vb = size_t{m.vertex_count} * sizeof(scene::Vertex);
      const size_t ib = size_t{m.index_count} * sizeof(uint32_t);
      std::memcpy(vertices_.bytes().data() + size_t{m.first_vertex} * sizeof(scene::Vertex),
                  scene.vertices().data() + m.first_vertex, vb);
      absolute_indices(m, scene.indices(), indices_.as<uint32_t>() + m.first_index);
      std::fill_n(vertex_mesh_.as<uint32_t>() + m.first_vertex, m.vertex_count, id);
      mesh_meta_.as<gpu::MeshMeta>()[id] = kEmptyMeta;
      stats_.bytes_uploaded += vb + ib + size_t{m.vertex_count} * sizeof(uint32_t) + sizeof(gpu::MeshMeta);
    } else {
      queued_.push_back(id);
    }
    if (new_textures) new_textures->push_back(m.texture_id);
  }
  stats_.meshes_resident += fresh_.size();
  stats_.meshes_uploaded = fresh_.size();
  return ok_status();
}

Status SceneGpu::record_uploads(const SceneData& scene, VkCommandBuffer cmd) {
  if (queued_.empty()) return ok_status();
  // In mesh order: meshes.bin stores neighbouring meshes' data next to each other, so copies merge.
  std::sort(queued_.begin(), queued_.end());
  const auto records = scene.mesh_records();
  const auto verts = std::as_bytes(scene.vertices());
  VkDeviceSize total = 0;
  for (uint32_t id : queued_) {
    const scene::MeshRecord& m = records[id];
    total += sizeof(gpu::MeshMeta);
    if (is_instanced(id)) continue;  // its geometry is its owner's
    total += uint64_t{m.vertex_count} * (sizeof(scene::Vertex) + sizeof(uint32_t)) +
             uint64_t{m.index_count} * sizeof(uint32_t);
  }
  if (staging_.size() < total) {
    // Grown, never shrunk: the largest frame so far (the first frame of a view) sets the size.
    auto b = GpuBuffer::create(*ctx_, std::max<VkDeviceSize>(total, staging_.size() * 2),
                               VK_BUFFER_USAGE_TRANSFER_SRC_BIT, MemoryUse::kHostVisible);
    if (!b) return b.error();
    staging_ = std::move(*b);
  }
  std::byte* dst = staging_.bytes().data();
  std::vector<VkBufferCopy> vregions, idregions, iregions, mregions;
  VkDeviceSize at = 0;
  // One kind of data at a time (all vertices, then all ids, then all indices, then the metadata entries), so
  // that meshes adjacent in meshes.bin give one copy region per kind and run: a region per mesh and kind made
  // the first frame's copies take most of a second on a 10^5-mesh view (each region is a separate copy).
  for (uint32_t id : queued_) {
    if (is_instanced(id)) continue;
    const scene::MeshRecord& m = records[id];
    const VkDeviceSize vb = uint64_t{m.vertex_count} * sizeof(scene::Vertex);
    const VkDeviceSize voff = uint64_t{m.first_vertex} * sizeof(scene::Vertex);
    std::memcpy(dst + at, verts.data() + voff, vb);
    add_region(vregions, at, voff, vb);
    at += vb;
  }
  for (uint32_t id : queued_) {
    if (is_instanced(id)) continue;
    const scene::MeshRecord& m = records[id];
    const VkDeviceSize idb = uint64_t{m.vertex_count} * sizeof(uint32_t);
    const VkDeviceSize idoff = uint64_t{m.first_vertex} * sizeof(uint32_t);
    std::fill_n(reinterpret_cast<uint32_t*>(dst + at), m.vertex_count, id);
    add_region(idregions, at, idoff, idb);
    at += idb;
  }
  for (uint32_t id : queued_) {
    if (is_instanced(id)) continue;
    const scene::MeshRecord& m = records[id];
    const VkDeviceSize ib = uint64_t{m.index_count} * sizeof(uint32_t);
    const VkDeviceSize ioff = uint64_t{m.first_index} * sizeof(uint32_t);
    absolute_indices(m, scene.indices(), reinterpret_cast<uint32_t*>(dst + at));
    add_region(iregions, at, ioff, ib);
    at += ib;
  }
  for (uint32_t id : queued_) {
    std::memcpy(dst + at, &kEmptyMeta, sizeof kEmptyMeta);
    add_region(mregions, at, VkDeviceSize{id} * sizeof(gpu::MeshMeta), sizeof kEmptyMeta);
    at += sizeof kEmptyMeta;
  }
  stats_.bytes_uploaded += total;
  queued_.clear();

  VkBuffer src = staging_.handle();
  copy_regions(cmd, src, vertices_.handle(), vregions);
  copy_regions(cmd, src, vertex_mesh_.handle(), idregions);
  copy_regions(cmd, src, indices_.handle(), iregions);
  copy_regions(cmd, src, mesh_meta_.handle(), mregions);
  VkMemoryBarrier b{};
  b.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
  b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  b.dstAccessMask = VK_ACCESS_VERTEX_ATTRIBUTE_READ_BIT | VK_ACCESS_INDEX_READ_BIT | VK_ACCESS_SHADER_READ_BIT |
                    VK_ACCESS_SHADER_WRITE_BIT;
  vkCmdPipelineBarrier(
      cmd, VK_PIPELINE_STAGE_TRANSFER_BIT,
      VK_PIPELINE_STAGE_VERTEX_INPUT_BIT | VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
      0, 1, &b, 0, nullptr, 0, nullptr);
  return ok_status();
}

void SceneGpu::write_draws(const SceneData& scene, std::span<const uint32_t> visible,
                           const std::array<double, 3>& camera, const ViewportSplit& split, TextureSlots& slots,
                           FrameRecording& rec) {
  // `drawn` holds mesh_count ids: the broad phase returns each mesh at most once.
  TS_ASSERT(visible.size() <= mesh_count_, "write_draws of %zu meshes of %u", visible.size(), mesh_count_);
  const size_t main_end = std::min<size_t>(split.main_end, visible.size());
  auto* mesh_out = meshes_.as<gpu::MeshGpu>();
  auto* drawn_out = drawn_.as<uint32_t>();
  const auto records = scene.mesh_records();
  uint32_t drawn_count = 0;
  for (const uint32_t id : visible) {
    const scene::MeshRecord& m = records[id];
    if (m.index_count == 0) continue;  // never drawn
    TS_ASSERT(is_resident(id), "mesh %u drawn before make_resident", id);
    gpu::MeshGpu& g = mesh_out[id];
    g.offset_x = static_cast<float>(m.origin[0] - camera[0]);
    g.offset_y = static_cast<float>(m.origin[1] - camera[1]);
    g.offset_z = static_cast<float>(m.origin[2] - camera[2]);
    g.texture_id = m.texture_id;
    const scene::MeshTransform t = scene.mesh_transform(id);
    g.rotation = {t.rotation[0], t.rotation[1], t.rotation[2], t.rotation[3]};
    g.scale = t.scale;
    g.texture_slot = slots.use(m.texture_id);
    g.reserved0 = g.reserved1 = 0;
    drawn_out[drawn_count++] = id;  // each mesh once, whichever passes draw it
  }
  // Two lists, one per pass, each sorted and merged on its own.
  uint32_t instance_at = 0;
  const auto main_list = write_list(scene, visible.first(main_end), 0, instance_at);
  const auto wide_list = write_list(scene, visible.subspan(main_end), main_list.second, instance_at);
  rec.main_count = main_list.second;
  rec.wide_first = main_list.second;
  rec.draw_count = main_list.second + wide_list.second;
  rec.mesh_count = drawn_count;
  rec.main_meshes = main_list.first;
  rec.wide_meshes = wide_list.first;
}

std::pair<uint32_t, uint32_t> SceneGpu::write_list(const SceneData& scene, std::span<const uint32_t> ids,
                                                   uint32_t draw_at, uint32_t& instance_at) {
  const auto records = scene.mesh_records();
  // Mesh id order: meshes.bin stores neighbouring meshes' indices next to each other, so neighbours in id
  // become one draw. The broad phase returns the meshes in quadtree order, which splits such runs (on the
  // default city a view's ~650 meshes are ~250 runs as returned, ~40 in id order). The order comes from a
  // bitset over the mesh ids, not a sort: O(meshes + id range / 64), and a sort of a view's list each frame
  // showed on a GPU's frame time (~0.1 ms of ~3 ms on the H200). The triangles a pass rasterizes are then in
  // the same order whatever order the broad phase returned and whichever mesh owns shared ranges.
  uint32_t meshes_listed = 0;
  size_t lo = in_list_.size(), hi = 0;
  for (uint32_t id : ids) {
    if (records[id].index_count == 0) continue;
    const size_t w = id >> 6;
    const uint64_t b = uint64_t{1} << (id & 63);
    if (in_list_[w] & b) continue;  // listed twice: drawn once
    in_list_[w] |= b;
    lo = std::min(lo, w);
    hi = std::max(hi, w);
    ++meshes_listed;
  }
  auto* draws = indirect_.as<VkDrawIndexedIndirectCommand>() + draw_at;
  uint32_t count = 0;
  bool open = false;  // whether draws[count - 1] is a run that the next adjacent mesh may extend
  grouped_.clear();
  for (size_t w = lo; w <= hi && w < in_list_.size(); ++w) {
    for (uint64_t bits = std::exchange(in_list_[w], 0); bits != 0; bits &= bits - 1) {
      const auto id = static_cast<uint32_t>(w * 64 + static_cast<size_t>(std::countr_zero(bits)));
      if (is_instanced(id)) {
        grouped_.push_back({records[id].first_index, records[id].index_count, id});
        continue;
      }
      emit_draw(records[id].first_index, records[id].index_count, draws, count, open);
    }
  }
  // Instances after the runs, one draw per shared range: their vertices carry the owner's id, so each instance
  // takes its mesh id from the instances buffer (scene.vert: firstInstance - 1 + the instance's index). A city's
  // trees or lamps, thousands of placements of a few meshes, become a few draws.
  std::sort(grouped_.begin(), grouped_.end());
  auto* inst = instances_.as<uint32_t>();
  for (size_t i = 0; i < grouped_.size();) {
    size_t j = i;
    while (j < grouped_.size() && grouped_[j][0] == grouped_[i][0] && grouped_[j][1] == grouped_[i][1]) {
      inst[instance_at + (j - i)] = grouped_[j][2];
      ++j;
    }
    const auto k = static_cast<uint32_t>(j - i);
    draws[count++] = VkDrawIndexedIndirectCommand{grouped_[i][1], k, grouped_[i][0], 0, instance_at + 1};
    instance_at += k;
    i = j;
  }
  return {meshes_listed, count};
}

void SceneGpu::emit_draw(uint32_t first_index, uint32_t index_count, VkDrawIndexedIndirectCommand* draws,
                         uint32_t& count, bool& open) const {
  // Owned ranges never overlap (make_resident), so "ends where this one starts" is exactly "adjacent".
  if (open && draws[count - 1].firstIndex + draws[count - 1].indexCount == first_index) {
    draws[count - 1].indexCount += index_count;
  } else {
    draws[count++] = VkDrawIndexedIndirectCommand{index_count, 1, first_index, 0, 0};
    open = true;
  }
}

}  // namespace texstream::render
