// SceneGpu's draw list on lavapipe (issue 5, few draws): meshes whose index ranges lie next to each other in
// meshes.bin become one indirect draw, per pass's list and in mesh id order whatever order the
// broad phase gave; indices are stored absolute and every vertex carries its mesh's id; the meshes instancing
// one range are one instanced draw per pass after the runs, their ids in the instances buffer; any other
// sharing of ranges is refused naming the mesh, and leaves nothing resident.
#include <gtest/gtest.h>

#include <array>
#include <memory>
#include <vector>

#include "texstream/render/frame/scene_passes.hpp"
#include "texstream/render/scene/broad_phase.hpp"
#include "texstream/render/scene/scene_data.hpp"
#include "texstream/render/scene/scene_gpu.hpp"
#include "texstream/render/scene/texture_slots.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

using namespace texstream;
using namespace texstream::render;

namespace {

// `n` one-triangle meshes, mesh i owning vertices and indices [3i, 3i + 3) (indices 2, 1, 0: relative, and not
// the identity, so an index left relative would show); then, per entry of `instances`, a mesh with the same
// ranges as that mesh.
SceneData triangles(uint32_t n, const std::vector<uint32_t>& instances = {}) {
  SceneData s;
  s.dir = "/nonexistent/test_scene";
  s.manifest.texture_format = TexelFormat::kRgba8;
  s.textures.push_back(scene::TextureRecord{16, 16, 5, static_cast<uint32_t>(TexelFormat::kRgba8)});
  s.colormap.push_back(0xff808080u);
  auto mesh = [](uint32_t first) {
    scene::MeshRecord m{};
    m.origin[0] = 100.0 * first;
    for (int a = 0; a < 3; ++a) {
      m.bounds_min[a] = -1;
      m.bounds_max[a] = 1;
    }
    m.first_vertex = first;
    m.vertex_count = 3;
    m.first_index = first;
    m.index_count = 3;
    return m;
  };
  for (uint32_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) {
      scene::Vertex v{};
      v.pos[0] = static_cast<float>(k);
      v.pos[1] = static_cast<float>(k == 2);
      s.meshes.vertices.push_back(v);
    }
    s.meshes.indices.insert(s.meshes.indices.end(), {2, 1, 0});
    s.meshes.meshes.push_back(mesh(3 * i));
  }
  for (uint32_t owner : instances) s.meshes.meshes.push_back(mesh(3 * owner));
  s.manifest.mesh_count = static_cast<uint32_t>(s.meshes.meshes.size());
  s.manifest.texture_count = 1;
  return s;
}

struct Gpu {
  std::unique_ptr<VulkanContext> ctx;
  SceneGpu scene;
};

std::unique_ptr<Gpu> make_gpu(const SceneData& s) {
  VulkanContextOptions o;
  o.validation = true;
  auto ctx = VulkanContext::create(o);
  EXPECT_TRUE(ctx.ok()) << (ctx.ok() ? "" : ctx.error().message);
  if (!ctx.ok()) return nullptr;
  auto g = std::make_unique<Gpu>();
  g->ctx = std::move(*ctx);
  auto sg = SceneGpu::create(*g->ctx, s);
  EXPECT_TRUE(sg.ok()) << (sg.ok() ? "" : sg.error().message);
  if (!sg.ok()) return nullptr;
  g->scene = std::move(*sg);
  return g;
}

struct Draw {
  uint32_t first_index, index_count, first_instance;
  uint32_t instance_count = 1;
  bool operator==(const Draw&) const = default;
};

std::vector<Draw> draws_of(const SceneGpu& g, uint32_t count) {
  std::vector<Draw> out;
  const auto* d = g.indirect().as<VkDrawIndexedIndirectCommand>();
  for (uint32_t i = 0; i < count; ++i) {
    EXPECT_EQ(d[i].vertexOffset, 0);
    out.push_back({d[i].firstIndex, d[i].indexCount, d[i].firstInstance, d[i].instanceCount});
  }
  return out;
}

// The mesh ids an instanced draw's instances read (scene.vert): instances[firstInstance - 1 ...].
std::vector<uint32_t> instance_ids(const SceneGpu& g, const Draw& d) {
  const uint32_t* ids = g.instances().as<uint32_t>();
  return {ids + d.first_instance - 1, ids + d.first_instance - 1 + d.instance_count};
}

}  // namespace

TEST(SceneDraws, AdjacentMeshesMergePerPartInIndexOrderAndInstancesDrawAfterTheRuns) {
  // Meshes 0-6 own their ranges; mesh 7 has mesh 4's. Meshes 2 and 5 are not in view.
  const SceneData s = triangles(7, {4});
  auto g = make_gpu(s);
  ASSERT_NE(g, nullptr);
  // The broad phase's order, split: [6 7 0 1 | 3 4] = touching the viewport, outside. 7 comes before 4, so 7
  // owns the shared ranges and 4 is the instance.
  const std::vector<uint32_t> visible{6, 7, 0, 1, 3, 4};
  ASSERT_TRUE(g->scene.make_resident(s, visible, nullptr).ok());
  EXPECT_TRUE(g->scene.is_instanced(4));
  EXPECT_FALSE(g->scene.is_instanced(7));
  FrameRecording rec;
  TextureSlots slots(s.texture_records().size());
  slots.begin_frame();
  g->scene.write_draws(s, visible, {0, 0, 0}, ViewportSplit{4}, slots, rec);
  // Every drawn mesh names its texture's table slot (one texture here: one slot, kept by the frame).
  const auto* mesh_gpu = g->scene.meshes().as<gpu::MeshGpu>();
  for (uint32_t id : visible) EXPECT_EQ(mesh_gpu[id].texture_slot, 0u) << "mesh " << id;
  EXPECT_EQ(slots.find(0), 0u);
  EXPECT_EQ(slots.in_use(), 1u);
  slots.release_unused([](uint32_t) { return false; });
  EXPECT_EQ(slots.in_use(), 1u) << "a texture drawn in the frame keeps its slot";

  // The main pass's list (6 7 0 1) in id order: 0 and 1 (indices 0-5) adjacent, one draw; 6 (18-20); 7
  // (12-14), the owner, not adjacent to 20. The wide pass's list (3 4): 3 (9-11); 4 (12-14), the instance, in
  // an instanced draw of its own after the runs (firstInstance 1: the first entry of the instances buffer).
  const std::vector<Draw> want{{0, 6, 0},
                               {18, 3, 0},
                               {12, 3, 0},  // main
                               {9, 3, 0},
                               {12, 3, 1, 1}};  // wide
  EXPECT_EQ(draws_of(g->scene, rec.draw_count), want);
  EXPECT_EQ(instance_ids(g->scene, want[4]), std::vector<uint32_t>{4});
  EXPECT_EQ(rec.main_count, 3u);
  EXPECT_EQ(rec.wide_first, 3u);
  EXPECT_EQ(rec.draw_count, 5u);
  EXPECT_EQ(rec.mesh_count, 6u);
  EXPECT_EQ(rec.main_meshes, 4u);
  EXPECT_EQ(rec.wide_meshes, 2u);
  // Each drawn mesh once, in the broad phase's order: what compact.comp visits.
  const uint32_t* drawn = g->scene.drawn().as<uint32_t>();
  EXPECT_EQ(std::vector<uint32_t>(drawn, drawn + rec.mesh_count), visible);

  // Without 4 and 7, the main list's 3 and 6 stay apart (5 is not in view) and 0 merges with nothing.
  const std::vector<uint32_t> fewer{6, 3, 0, 1};
  g->scene.write_draws(s, fewer, {0, 0, 0}, ViewportSplit{4}, slots, rec);
  EXPECT_EQ(draws_of(g->scene, rec.draw_count), (std::vector<Draw>{{0, 6, 0}, {9, 3, 0}, {18, 3, 0}}));
  EXPECT_EQ(rec.wide_first, 3u);
  EXPECT_EQ(rec.draw_count, 3u);  // nothing reaches outside

  // Stored absolute (relative 2 1 0 + first vertex), each vertex carrying its owner's id.
  const uint32_t* idx = g->scene.indices().as<uint32_t>();
  const uint32_t* vm = g->scene.vertex_mesh().as<uint32_t>();
  EXPECT_EQ((std::array<uint32_t, 3>{idx[12], idx[13], idx[14]}), (std::array<uint32_t, 3>{14, 13, 12}));
  EXPECT_EQ((std::array<uint32_t, 3>{vm[12], vm[13], vm[14]}), (std::array<uint32_t, 3>{7, 7, 7}));
  EXPECT_EQ((std::array<uint32_t, 3>{vm[18], vm[19], vm[20]}), (std::array<uint32_t, 3>{6, 6, 6}));
  EXPECT_EQ(g->ctx->validation_errors(), 0u);
}

TEST(SceneDraws, TheInstancesOfOneRangeAreOneInstancedDrawPerPass) {
  // Meshes 0-3 own their ranges; 4, 5, 6 instance mesh 1 and 7, 8 mesh 3.
  const SceneData s = triangles(4, {1, 1, 1, 3, 3});
  auto g = make_gpu(s);
  ASSERT_NE(g, nullptr);
  const std::vector<uint32_t> visible{8, 5, 1, 6, 7, 3, 4, 0};
  ASSERT_TRUE(g->scene.make_resident(s, visible, nullptr).ok());
  FrameRecording rec;
  TextureSlots slots(s.texture_records().size());
  // Main pass: 8 5 1 6 7 3 (8 came first, so it owns mesh 3's ranges and 3 and 7 instance them; 5 owns mesh 1's,
  // 1 and 6 instance them). Wide pass: 4 0.
  g->scene.write_draws(s, visible, {0, 0, 0}, ViewportSplit{6}, slots, rec);
  const std::vector<Draw> d = draws_of(g->scene, rec.draw_count);
  // Main: the owners 5 (3-5) and 8 (9-11) in id order are not adjacent: two runs; then (3-5) x {1, 6},
  // (9-11) x {3, 7}. Wide: 0 (0-2), then (3-5) x {4}.
  const std::vector<Draw> want{{3, 3, 0}, {9, 3, 0}, {3, 3, 1, 2}, {9, 3, 3, 2}, {0, 3, 0}, {3, 3, 5, 1}};
  ASSERT_EQ(d, want);
  EXPECT_EQ(instance_ids(g->scene, d[2]), (std::vector<uint32_t>{1, 6}));
  EXPECT_EQ(instance_ids(g->scene, d[3]), (std::vector<uint32_t>{3, 7}));
  EXPECT_EQ(instance_ids(g->scene, d[5]), (std::vector<uint32_t>{4}));
  EXPECT_EQ(rec.main_count, 4u);
  EXPECT_EQ(rec.draw_count, 6u);
  EXPECT_EQ(g->ctx->validation_errors(), 0u);
}

TEST(SceneDraws, AnInstanceSeenBeforeItsOwnerOwnsTheRangesInstead) {
  // Whichever mesh is made resident first owns the ranges; the other is the instance.
  const SceneData s = triangles(2, {1});
  auto g = make_gpu(s);
  ASSERT_NE(g, nullptr);
  ASSERT_TRUE(g->scene.make_resident(s, std::vector<uint32_t>{2}, nullptr).ok());
  ASSERT_TRUE(g->scene.make_resident(s, std::vector<uint32_t>{1, 0}, nullptr).ok());
  EXPECT_TRUE(g->scene.is_instanced(1));
  EXPECT_FALSE(g->scene.is_instanced(2));
  EXPECT_EQ(g->scene.vertex_mesh().as<uint32_t>()[3], 2u);
}

TEST(SceneDraws, PartlySharedRangesAreRefusedNamingTheMeshAndLeaveNothingResident) {
  SceneData s = triangles(3, {0});  // mesh 3 instances mesh 0
  // Mesh 2's indices start inside mesh 1's: overlapping, not the same ranges. Its own check passes (its
  // indices are below its vertex count).
  s.meshes.meshes[2].first_index = 4;
  s.meshes.meshes[2].index_count = 3;
  s.meshes.indices[4] = 0;
  s.meshes.indices[5] = 1;
  s.meshes.indices[6] = 2;
  auto g = make_gpu(s);
  ASSERT_NE(g, nullptr);
  const Status st = g->scene.make_resident(s, std::vector<uint32_t>{0, 3, 1, 2}, nullptr);
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(st.error().message.find("meshes.bin: mesh 2"), std::string::npos) << st.error().message;
  for (uint32_t id = 0; id < 4; ++id) {
    EXPECT_FALSE(g->scene.is_resident(id)) << "mesh " << id;
    EXPECT_FALSE(g->scene.is_instanced(id)) << "mesh " << id;
  }
  // The refused call's claims were undone: its other meshes can still become resident, and mesh 3 now owns
  // the ranges it only instanced before.
  ASSERT_TRUE(g->scene.make_resident(s, std::vector<uint32_t>{3, 1}, nullptr).ok());
  ASSERT_TRUE(g->scene.make_resident(s, std::vector<uint32_t>{0}, nullptr).ok());
  EXPECT_FALSE(g->scene.is_instanced(3));
  EXPECT_TRUE(g->scene.is_instanced(0));
  EXPECT_FALSE(g->scene.is_instanced(1));
  EXPECT_EQ(g->scene.vertex_mesh().as<uint32_t>()[0], 3u);
  EXPECT_EQ(g->scene.vertex_mesh().as<uint32_t>()[3], 1u);
}
