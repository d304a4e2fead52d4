// Mapped scene reading (issue 6, start-up independent of the scene size): the mapped readers see exactly what
// the reading ones do and refuse the same bad input with the same file + record; the mesh index round-trips,
// is refused when stale or broken (so it is rebuilt, never trusted blindly); a BroadPhase over a mapped index
// answers exactly as one built in memory and as brute force; SceneData::open defers mesh checks to
// check_mesh() without losing any.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <random>

#include "test_temp_dir.hpp"
#include "texstream/common/mesh_index.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/render/scene/broad_phase.hpp"
#include "texstream/render/scene/camera.hpp"
#include "texstream/render/scene/scene_data.hpp"

namespace fs = std::filesystem;
using namespace texstream;
using namespace texstream::scene;

namespace {

constexpr double kX = 392000.0, kY = 5820000.0;  // map coordinates: floats have 0.5 m steps here

class SceneMappedTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = test::fresh_test_dir("texstream_scene_mapped"); }
  void TearDown() override { fs::remove_all(dir_); }

  template <class T>
  void patch(const fs::path& p, size_t offset, const T& v) {
    std::fstream f(p, std::ios::binary | std::ios::in | std::ios::out);
    ASSERT_TRUE(f.good());
    f.seekp(static_cast<std::streamoff>(offset));
    f.write(reinterpret_cast<const char*>(&v), sizeof v);
  }

  // A city of `n` one-quad meshes on a jittered grid (`spacing` m), one texture each, with its texture table,
  // colormap and manifest: a complete scene for SceneData.
  MeshData write_city(uint32_t n, double spacing, uint32_t seed = 1) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> jitter(-0.4, 0.4);
    MeshData d;
    const auto side = static_cast<uint32_t>(std::ceil(std::sqrt(static_cast<double>(n))));
    for (uint32_t m = 0; m < n; ++m) {
      MeshRecord r{};
      r.origin[0] = kX + (m % side + jitter(rng)) * spacing;
      r.origin[1] = kY + (m / side + jitter(rng)) * spacing;
      r.origin[2] = 34.0;
      r.bounds_max[0] = 10;
      r.bounds_max[2] = 5 + static_cast<float>(m % 7);
      r.first_vertex = 4 * m;
      r.vertex_count = 4;
      r.first_index = 6 * m;
      r.index_count = 6;
      r.texture_id = m;
      d.meshes.push_back(r);
      const float xs[4] = {0, 10, 10, 0}, zs[4] = {0, 0, r.bounds_max[2], r.bounds_max[2]};
      for (int v = 0; v < 4; ++v)
        d.vertices.push_back(Vertex{{xs[v], 0, zs[v]}, {0, -1, 0}, {xs[v] / 10, zs[v] > 0 ? 0.0f : 1.0f}});
      for (uint32_t i : {0u, 1u, 2u, 0u, 2u, 3u}) d.indices.push_back(i);
    }
    EXPECT_TRUE(write_meshes(dir_, d).ok());
    std::vector<TextureRecord> t(n, TextureRecord{64, 32, full_mip_count(64, 32), 2});
    EXPECT_TRUE(write_texture_table(dir_, t).ok());
    std::vector<uint32_t> c(n);
    for (uint32_t i = 0; i < n; ++i) c[i] = 0xff000000u | i;
    EXPECT_TRUE(write_colormap(dir_, c).ok());
    Manifest man;
    man.mesh_count = n;
    man.texture_count = n;
    man.texture_format = TexelFormat::kBc1;
    man.origin = {kX, kY, 34};
    man.bounds_min = {kX - spacing, kY - spacing, 0};
    man.bounds_max = {kX + (side + 1) * spacing, kY + (side + 1) * spacing, 100};
    EXPECT_TRUE(write_manifest(dir_, man).ok());
    return d;
  }

  fs::path dir_;
};

void expect_fails(const auto& r, const std::string& needle) {
  ASSERT_FALSE(r.ok()) << "accepted input that should fail naming '" << needle << "'";
  EXPECT_NE(r.error().message.find(needle), std::string::npos) << "message: " << r.error().message;
}

std::vector<uint32_t> brute_force(std::span<const MeshRecord> meshes, const render::Frustum& f,
                                  const std::array<double, 3>& cam) {
  std::vector<uint32_t> out;
  for (uint32_t i = 0; i < meshes.size(); ++i) {
    double lo[3], hi[3];
    mesh_box(meshes[i], lo, hi);
    const glm::vec3 a(static_cast<float>(lo[0] - cam[0]), static_cast<float>(lo[1] - cam[1]),
                      static_cast<float>(lo[2] - cam[2]));
    const glm::vec3 b(static_cast<float>(hi[0] - cam[0]), static_cast<float>(hi[1] - cam[1]),
                      static_cast<float>(hi[2] - cam[2]));
    if (f.classify(a, b) != render::Frustum::Side::kOutside) out.push_back(i);
  }
  return out;
}

}  // namespace

TEST_F(SceneMappedTest, MappedReadersSeeWhatTheReadersSee) {
  const MeshData d = write_city(50, 20);
  auto mapped = map_meshes(dir_);
  ASSERT_TRUE(mapped.ok()) << mapped.error().message;
  ASSERT_EQ(mapped->meshes.size(), 50u);
  ASSERT_EQ(mapped->vertices.size(), d.vertices.size());
  ASSERT_EQ(mapped->indices.size(), d.indices.size());
  EXPECT_EQ(0, std::memcmp(mapped->meshes.data(), d.meshes.data(), d.meshes.size() * sizeof(MeshRecord)));
  EXPECT_EQ(0, std::memcmp(mapped->vertices.data(), d.vertices.data(), d.vertices.size() * sizeof(Vertex)));
  EXPECT_TRUE(std::equal(d.indices.begin(), d.indices.end(), mapped->indices.begin()));
  for (size_t i = 0; i < 50; ++i) EXPECT_TRUE(mapped->check_mesh(i).ok());

  auto table = map_texture_table(dir_);
  ASSERT_TRUE(table.ok()) << table.error().message;
  auto read_table = read_texture_table(dir_);
  ASSERT_TRUE(read_table.ok());
  ASSERT_EQ(table->textures.size(), read_table->size());
  EXPECT_EQ(0, std::memcmp(table->textures.data(), read_table->data(), read_table->size() * sizeof(TextureRecord)));
  auto colours = map_colormap(dir_, 50);
  ASSERT_TRUE(colours.ok()) << colours.error().message;
  EXPECT_EQ(colours->rgba[49], 0xff000031u);
  expect_fails(map_colormap(dir_, 51), "51 textures");
  expect_fails(map_meshes(dir_ / "nowhere"), "meshes.bin");
  EXPECT_EQ(map_meshes(dir_ / "nowhere").error().code, ErrorCode::kNotFound);
}

TEST_F(SceneMappedTest, HeadersAreCheckedAtOnceAndMeshesWhenAsked) {
  write_city(4, 20);
  const fs::path p = dir_ / "meshes.bin";
  const size_t rec2 = sizeof(MeshFileHeader) + 2 * sizeof(MeshRecord);
  patch(p, offsetof(MeshFileHeader, magic), uint64_t{0x1234});
  expect_fails(map_meshes(dir_), "magic");
  write_city(4, 20);
  fs::resize_file(p, fs::file_size(p) - 1);
  expect_fails(map_meshes(dir_), "truncated");
  fs::resize_file(p, 10);
  expect_fails(map_meshes(dir_), "shorter than its header");

  // A record's fault is found by check_mesh, for that mesh only, with read_meshes' message.
  write_city(4, 20);
  patch(p, rec2 + offsetof(MeshRecord, first_index), uint32_t{0xffffffffu});
  auto m = map_meshes(dir_);
  ASSERT_TRUE(m.ok()) << m.error().message;
  EXPECT_TRUE(m->check_mesh(1).ok());
  EXPECT_TRUE(m->check_mesh(3).ok());
  expect_fails(m->check_mesh(2), "meshes.bin: mesh 2: index range");
  expect_fails(read_meshes(dir_), "meshes.bin: mesh 2: index range");

  write_city(4, 20);
  patch(p, sizeof(MeshFileHeader) + 4 * sizeof(MeshRecord) + 13 * sizeof(Vertex),
        std::numeric_limits<float>::infinity());
  m = map_meshes(dir_);
  ASSERT_TRUE(m.ok());
  expect_fails(m->check_mesh(3), "mesh 3: vertex 1 is not finite");

  write_city(4, 20);
  patch(dir_ / "textures.bin", sizeof(TextureFileHeader) + 2 * sizeof(TextureRecord), uint32_t{0});
  expect_fails(map_texture_table(dir_), "textures.bin: texture 2: extent");

  // Something that is not a regular file is refused naming it, at once: opening a FIFO must not wait for a
  // writer (the server maps textures.bin too, and read_texture_table refused one the same way).
  fs::remove(dir_ / "textures.bin");
  ASSERT_EQ(::mkfifo((dir_ / "textures.bin").c_str(), 0600), 0);
  expect_fails(map_texture_table(dir_), "textures.bin: not a regular file");
  EXPECT_EQ(map_texture_table(dir_).error().code, ErrorCode::kNotAFile);
}

TEST_F(SceneMappedTest, MeshIndexRoundTripsAndIsRefusedWhenStaleOrBroken) {
  const MeshData d = write_city(3000, 15);
  expect_fails(map_mesh_index(dir_, 3000), "mesh_index.bin");
  EXPECT_EQ(map_mesh_index(dir_, 3000).error().code, ErrorCode::kNotFound);
  const MeshIndex built = build_mesh_index(d.meshes);
  ASSERT_GT(built.nodes.size(), 3000u / kMeshIndexLeafMeshes);
  ASSERT_TRUE(write_mesh_index(dir_, built.view()).ok());
  auto m = map_mesh_index(dir_, 3000);
  ASSERT_TRUE(m.ok()) << m.error().message;
  ASSERT_EQ(m->view.nodes.size(), built.nodes.size());
  EXPECT_EQ(0, std::memcmp(m->view.nodes.data(), built.nodes.data(), built.nodes.size() * sizeof(MeshIndexNode)));
  EXPECT_TRUE(std::equal(built.order.begin(), built.order.end(), m->view.order.begin()));
  EXPECT_EQ(m->view.depth, built.depth);
  expect_fails(map_mesh_index(dir_, 2999), "2999");

  const fs::path idx = dir_ / "mesh_index.bin";
  const size_t nodes_at = sizeof(MeshIndexHeader);
  const size_t order_at = nodes_at + built.nodes.size() * sizeof(MeshIndexNode);
  auto rewrite = [&] { ASSERT_TRUE(write_mesh_index(dir_, built.view()).ok()); };
  // A repeated id (one mesh lost, another drawn twice).
  patch(idx, order_at + 5 * sizeof(uint32_t), built.order[6]);
  expect_fails(map_mesh_index(dir_, 3000), "repeated");
  rewrite();
  patch(idx, order_at + 5 * sizeof(uint32_t), uint32_t{3000});
  expect_fails(map_mesh_index(dir_, 3000), "out of range");
  // A child pointing back at an ancestor (a cycle) or past the nodes.
  rewrite();
  patch(idx, nodes_at + offsetof(MeshIndexNode, first_child), uint32_t{0});
  expect_fails(map_mesh_index(dir_, 3000), "node 0: children");
  rewrite();
  patch(idx, nodes_at + offsetof(MeshIndexNode, first_child), static_cast<uint32_t>(built.nodes.size()));
  expect_fails(map_mesh_index(dir_, 3000), "node 0: children");
  // Children that do not cut their parent's range.
  rewrite();
  const uint32_t c0 = built.nodes[0].first_child;
  patch(idx, nodes_at + c0 * sizeof(MeshIndexNode) + offsetof(MeshIndexNode, end), built.nodes[c0].end - 1);
  expect_fails(map_mesh_index(dir_, 3000), "mesh_index.bin: node");
  rewrite();
  patch(idx, nodes_at + offsetof(MeshIndexNode, min), std::numeric_limits<double>::quiet_NaN());
  expect_fails(map_mesh_index(dir_, 3000), "box not finite");
  rewrite();
  fs::resize_file(idx, fs::file_size(idx) - 4);
  expect_fails(map_mesh_index(dir_, 3000), "does not hold");

  // Stale: another city of the same size in meshes.bin (the index no longer describes its boxes).
  rewrite();
  ASSERT_TRUE(map_mesh_index(dir_, 3000).ok());
  write_city(3000, 15, /*seed=*/2);
  expect_fails(map_mesh_index(dir_, 3000), "stale");
}

TEST_F(SceneMappedTest, BroadPhaseOverTheMappedIndexEqualsBuiltAndBruteForce) {
  const MeshData d = write_city(20000, 8);
  ASSERT_TRUE(write_mesh_index(dir_, build_mesh_index(d.meshes).view()).ok());
  auto mapped = map_meshes(dir_);
  ASSERT_TRUE(mapped.ok());
  auto index = map_mesh_index(dir_, mapped->meshes.size());
  ASSERT_TRUE(index.ok()) << index.error().message;
  const render::BroadPhase from_file(mapped->meshes, std::move(*index));
  const render::BroadPhase built(d.meshes);
  EXPECT_TRUE(from_file.from_file());
  EXPECT_FALSE(built.from_file());
  EXPECT_EQ(from_file.node_count(), built.node_count());
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> pos(-200, 1400), angle(0, 360);
  int non_empty = 0;
  for (int v = 0; v < 40; ++v) {
    const std::array<double, 3> cam{kX + pos(rng), kY + pos(rng), 60.0};
    const glm::mat4 view = render::view_rotation(render::forward_from_angles(angle(rng), -20));
    const auto f = render::Frustum::from_matrix(render::perspective_reversed_z(60, 16.0 / 9.0, 0.5, 600.0) * view);
    std::vector<uint32_t> a, b, c;
    from_file.query(f, cam, a, nullptr, v % 2 == 0);
    built.query(f, cam, b);
    EXPECT_EQ(a, b) << "view " << v;
    std::sort(a.begin(), a.end());
    EXPECT_EQ(a, brute_force(d.meshes, f, cam)) << "view " << v;
    non_empty += !a.empty();
  }
  EXPECT_GE(non_empty, 10);
}

TEST_F(SceneMappedTest, OpenedSceneDefersMeshChecksAndKeepsTheIndex) {
  const MeshData d = write_city(200, 20);
  // Mesh 150 names a texture that does not exist: load() refuses the scene, open() only that mesh.
  patch(dir_ / "meshes.bin", sizeof(MeshFileHeader) + 150 * sizeof(MeshRecord) + offsetof(MeshRecord, texture_id),
        uint32_t{999});
  expect_fails(render::SceneData::load(dir_), "mesh 150 names texture 999");
  auto s = render::SceneData::open(dir_);
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_TRUE(s->is_mapped());
  EXPECT_TRUE(s->meshes.meshes.empty());  // nothing read into the loaded form
  ASSERT_EQ(s->mesh_records().size(), 200u);
  EXPECT_EQ(s->colours()[7], 0xff000007u);
  EXPECT_EQ(s->shapes().size(), 200u);
  EXPECT_TRUE(s->check_mesh(149).ok());
  expect_fails(s->check_mesh(150), "meshes.bin: mesh 150 names texture 999");
  render::SceneData copy = *s;
  expect_fails(copy.make_loaded(), "mesh 150");

  // The first BroadPhase of an opened scene builds the tree and keeps it; the next one maps it.
  EXPECT_FALSE(fs::exists(dir_ / "mesh_index.bin"));
  auto first = render::BroadPhase::for_scene(*s);
  EXPECT_FALSE(first->from_file());
  EXPECT_TRUE(fs::exists(dir_ / "mesh_index.bin"));
  auto second = render::BroadPhase::for_scene(*s);
  EXPECT_TRUE(second->from_file());
  EXPECT_EQ(second->node_count(), first->node_count());
}

// split_and_drop_unsampled is split_by_viewport and then drop_unsampled in one pass: the same ids in the same
// order and the same runs, on one thread and (from kParallelMinMeshes ids on) on all of them. Random boxes from
// 1 cm (far ones have no sample) to 60 m, all around the camera (some behind it, some straddling the viewport).
TEST(DropUnsampled, OnePassEqualsTheSplitThenTheDrop) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> pos(-800, 800), up(-20, 80), angle(0, 360);
  std::uniform_real_distribution<float> half(0.005f, 30.0f);
  for (const size_t n : {size_t{5000}, render::BroadPhase::kParallelMinMeshes + 10000}) {
    std::vector<MeshRecord> meshes(n);
    for (MeshRecord& m : meshes) {
      m = MeshRecord{};
      m.origin[0] = kX + pos(rng);
      m.origin[1] = kY + pos(rng);
      m.origin[2] = up(rng);
      for (int a = 0; a < 3; ++a) {
        m.bounds_min[a] = -half(rng);
        m.bounds_max[a] = half(rng);
      }
    }
    const render::BroadPhase bp(meshes);
    std::vector<uint32_t> all(n);
    for (uint32_t i = 0; i < n; ++i) all[i] = i;
    for (int v = 0; v < 4; ++v) {
      std::shuffle(all.begin(), all.end(), rng);
      const std::array<double, 3> cam{kX + pos(rng) * 0.2, kY + pos(rng) * 0.2, 40.0};
      const glm::mat4 view = render::view_rotation(render::forward_from_angles(angle(rng), -15));
      const glm::mat4 proj = render::perspective_reversed_z(60, 16.0 / 9.0, 0.5, 2000.0);
      const glm::mat4 wide = render::perspective_reversed_z(90, 16.0 / 9.0, 0.5, 2000.0);
      const render::SampleGrid main{proj * view, 320, 180, render::SampleGrid::margin_px_for(8)};
      const render::SampleGrid wide_grid{wide * view, 160, 90, render::SampleGrid::margin_px_for(8)};
      const auto viewport = render::Frustum::from_matrix(proj * view);
      std::vector<uint32_t> one = all, two = all;
      one.push_back(static_cast<uint32_t>(n + 3));  // not a mesh of the tree: both drop it
      two.push_back(static_cast<uint32_t>(n + 3));
      const render::ViewportSplit split = bp.split_by_viewport(viewport, cam, two);
      const render::ViewportSplit dropped = bp.drop_unsampled(main, wide_grid, cam, two, split);
      const render::ViewportSplit fused = bp.split_and_drop_unsampled(viewport, main, wide_grid, cam, one);
      EXPECT_EQ(one, two) << n << " view " << v;
      EXPECT_EQ(fused.main_end, dropped.main_end) << n << " view " << v;
      // The case is not trivial: both runs hold meshes, and meshes were dropped from each.
      EXPECT_GT(dropped.main_end, 0u);
      EXPECT_LT(dropped.main_end, two.size());
      EXPECT_LT(dropped.main_end, split.main_end);
      EXPECT_LT(two.size() - dropped.main_end, all.size() - split.main_end);
    }
  }
}

// drop_unsampled: a mesh whose screen rectangle holds no pixel centre of its pass is dropped, one that holds
// one is kept, one reaching behind the camera is kept; the runs keep their order and their new ends.
TEST(DropUnsampled, KeepsExactlyTheMeshesThatCanCoverAPixelCentre) {
  // A 4x4 pixel grid looking north from (kX, kY, 0): 90 degrees, so the pixel centres at ndc +-0.25, +-0.75.
  const glm::mat4 view = render::view_rotation(render::forward_from_angles(0, 0));
  const glm::mat4 proj = render::perspective_reversed_z(90, 1.0, 0.1, 1000.0);
  render::SampleGrid grid{proj * view, 4, 4, render::SampleGrid::margin_px_for(4)};  // 1/8 px: 4 sub-pixel bits
  const std::array<double, 3> cam{kX, kY, 0};
  auto quad = [](double x, double z, double dist, float half) {  // facing the camera, centre at ndc (x, z)/dist
    MeshRecord m{};
    m.origin[0] = kX + x;
    m.origin[1] = kY + dist;
    m.origin[2] = z;
    m.bounds_min[0] = m.bounds_min[2] = -half;
    m.bounds_max[0] = m.bounds_max[2] = half;
    return m;
  };
  std::vector<MeshRecord> meshes = {
      quad(0.0, 0.0, 100, 1.0f),    // 0: ndc 0 +- 0.01: between the centres at +-0.25 -> dropped
      quad(25.0, 25.0, 100, 1.0f),  // 1: ndc (0.25, 0.25) +- 0.01: on a centre -> kept
      quad(0.0, 0.0, 100, 30.0f),   // 2: ndc +-0.3: holds the centres at +-0.25 -> kept
      quad(50.0, 0.0, 100, 1.0f),   // 3: ndc x 0.5: between 0.25 and 0.75 -> dropped
      quad(0.0, 0.0, 0.05, 1.0f),   // 4: reaches behind the camera plane -> kept
      quad(14.1, 25.0, 100, 0.9f),  // 5: pixel x [2.264, 2.300]: 0.2 px short of the centre 2.5 -> dropped
  };
  const render::BroadPhase bp(meshes);
  std::vector<uint32_t> ids = {0, 1, 2, 3, 4, 5};
  // Runs: 0..3 touching the viewport (main grid), 4..5 outside (wide grid = the same here).
  const render::ViewportSplit split = bp.drop_unsampled(grid, grid, cam, ids, render::ViewportSplit{4});
  EXPECT_EQ(ids, (std::vector<uint32_t>{1, 2, 4}));
  EXPECT_EQ(split.main_end, 2u);
  // A rectangle ending 1/64 pixel short of a centre is kept (snapping may reach it) ...
  meshes[5] = quad(23.72, 25.0, 100, 0.5f);  // pixel x up to 2.4844
  const render::BroadPhase bp2(meshes);
  ids = {5};
  bp2.drop_unsampled(grid, grid, cam, ids, render::ViewportSplit{1});
  EXPECT_EQ(ids, (std::vector<uint32_t>{5}));
  // ... but not on a device snapping to 1/256 pixel, whose margin is 1/128.
  grid.margin_px = render::SampleGrid::margin_px_for(8);
  EXPECT_DOUBLE_EQ(grid.margin_px, 1.0 / 128.0);
  bp2.drop_unsampled(grid, grid, cam, ids, render::ViewportSplit{1});
  EXPECT_TRUE(ids.empty());
}
