// Broad phase: frustum maths and the grid query at map coordinates.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "texstream/render/scene/broad_phase.hpp"
#include "texstream/render/scene/camera.hpp"

using namespace texstream;
using namespace texstream::render;

namespace {

scene::MeshRecord mesh_at(double x, double y, double z) {
  scene::MeshRecord m{};
  m.origin[0] = x;
  m.origin[1] = y;
  m.origin[2] = z;
  for (int a = 0; a < 3; ++a) {
    m.bounds_min[a] = -1.0f;
    m.bounds_max[a] = 1.0f;
  }
  return m;
}

constexpr double kX = 392000.0, kY = 5820000.0;  // Berlin UTM: floats have 0.5 m steps here

}  // namespace

TEST(Camera, ForwardFollowsYawAndPitch) {
  const glm::vec3 north = forward_from_angles(0, 0);
  EXPECT_NEAR(north.y, 1.0f, 1e-6f);
  const glm::vec3 east = forward_from_angles(90, 0);
  EXPECT_NEAR(east.x, 1.0f, 1e-6f);
  const glm::vec3 up = forward_from_angles(0, 90);
  EXPECT_NEAR(up.z, 1.0f, 1e-6f);
}

TEST(Camera, ReversedZMapsNearToOneAndFarToZero) {
  const glm::mat4 p = perspective_reversed_z(60, 1.0, 1.0, 1000.0);
  glm::vec4 n = p * glm::vec4(0, 0, -1, 1);
  glm::vec4 f = p * glm::vec4(0, 0, -1000, 1);
  EXPECT_NEAR(n.z / n.w, 1.0f, 1e-6f);
  EXPECT_NEAR(f.z / f.w, 0.0f, 1e-6f);
  // The view looking north puts a point straight ahead at the screen centre, in front.
  const glm::mat4 v = view_rotation(forward_from_angles(0, 0));
  glm::vec4 c = p * v * glm::vec4(0, 10, 0, 1);
  EXPECT_NEAR(c.x / c.w, 0.0f, 1e-6f);
  EXPECT_NEAR(c.y / c.w, 0.0f, 1e-6f);
  EXPECT_GT(c.w, 0.0f);
}

TEST(BroadPhase, KeepsMeshesInFrontAndDropsThoseBehindOrAside) {
  std::vector<scene::MeshRecord> meshes;
  meshes.push_back(mesh_at(kX, kY + 50, 0));                                             // 0: ahead
  meshes.push_back(mesh_at(kX, kY - 50, 0));                                             // 1: behind
  meshes.push_back(mesh_at(kX + 500, kY + 10, 0));                                       // 2: far to the right
  meshes.push_back(mesh_at(kX + 5, kY + 300, 0));                                        // 3: ahead, slightly right
  meshes.push_back(mesh_at(kX, kY + 30000, 0));                                          // 4: beyond the far plane
  for (int i = 0; i < 200; ++i) meshes.push_back(mesh_at(kX - 2000 - i, kY - 2000, 0));  // cells far away
  BroadPhase bp(meshes);
  CameraPose pose{{kX, kY, 0}, 0, 0};
  const Camera cam = make_camera(pose, CameraLens{60, 75, 16.0 / 9.0, 1, 20000});
  std::vector<uint32_t> out;
  bp.query(Frustum::from_matrix(cam.wide_proj * cam.view), cam.position, out);
  std::sort(out.begin(), out.end());
  EXPECT_EQ(out, (std::vector<uint32_t>{0, 3}));
}

TEST(BroadPhase, MeshContainingTheCameraIsKept) {
  std::vector<scene::MeshRecord> meshes{mesh_at(kX, kY, 0)};
  BroadPhase bp(meshes);
  const Camera cam = make_camera(CameraPose{{kX, kY, 0.5}, 45, -10}, CameraLens{});
  std::vector<uint32_t> out;
  bp.query(Frustum::from_matrix(cam.wide_proj * cam.view), cam.position, out);
  EXPECT_EQ(out, std::vector<uint32_t>{0});
}

// The wide query's survivors split by the viewport's frustum: touching it, inside or straddling (main pass),
// then outside but in the wide frustum (wide pass): a straddling mesh is in the viewport, not outside it. Main FOV 60
// deg vertical at 16:9 is about 45.7 deg to each side; the wide one (75 deg) about 53.8 deg.
TEST(BroadPhase, SplitByViewportPutsStraddlingMeshesWithTheInsideOnes) {
  auto at_angle = [](double deg, double dist) {
    const double r = deg * M_PI / 180.0;
    return mesh_at(kX + dist * std::sin(r), kY + dist * std::cos(r), 0);
  };
  std::vector<scene::MeshRecord> meshes{
      at_angle(0, 50),     // 0: straight ahead: inside
      at_angle(45.7, 80),  // 1: on the viewport's right edge: straddles
      at_angle(50, 100),   // 2: between the viewport's and the wide FOV's edge: outside the viewport
      at_angle(-10, 200),  // 3: ahead, a little left: inside
      at_angle(-50, 100),  // 4: left, between the two edges: outside the viewport
      at_angle(180, 50),   // 5: behind: not even in the wide frustum
  };
  BroadPhase bp(meshes);
  const Camera cam = make_camera(CameraPose{{kX, kY, 0}, 0, 0}, CameraLens{60, 75, 16.0 / 9.0, 1, 20000});
  std::vector<uint32_t> ids;
  bp.query(Frustum::from_matrix(cam.wide_proj * cam.view), cam.position, ids);
  ASSERT_EQ(ids.size(), 5u);
  const ViewportSplit split = bp.split_by_viewport(Frustum::from_matrix(cam.proj * cam.view), cam.position, ids);
  ASSERT_EQ(ids.size(), 5u);
  EXPECT_EQ(split.main_end, 3u);
  std::vector<uint32_t> touching(ids.begin(), ids.begin() + split.main_end);
  std::sort(touching.begin(), touching.end());
  EXPECT_EQ(touching, (std::vector<uint32_t>{0, 1, 3}));
  std::vector<uint32_t> outside(ids.begin() + split.main_end, ids.end());
  std::sort(outside.begin(), outside.end());
  EXPECT_EQ(outside, (std::vector<uint32_t>{2, 4}));
}

namespace {

// Brute force: every mesh box against the frustum, camera-relative in double first (what the tree must equal).
std::vector<uint32_t> brute_force(const std::vector<scene::MeshRecord>& meshes, const Frustum& f,
                                  const std::array<double, 3>& cam) {
  std::vector<uint32_t> out;
  for (uint32_t i = 0; i < meshes.size(); ++i) {
    glm::vec3 lo, hi;
    for (int a = 0; a < 3; ++a) {
      lo[a] = static_cast<float>(meshes[i].origin[a] + static_cast<double>(meshes[i].bounds_min[a]) - cam[a]);
      hi[a] = static_cast<float>(meshes[i].origin[a] + static_cast<double>(meshes[i].bounds_max[a]) - cam[a]);
    }
    if (f.classify(lo, hi) != Frustum::Side::kOutside) out.push_back(i);
  }
  return out;
}

std::vector<scene::MeshRecord> random_city(uint32_t n, uint32_t seed) {
  std::vector<scene::MeshRecord> meshes;
  uint64_t s = seed * 0x9E3779B97F4A7C15ull + 1;
  auto next = [&] {  // xorshift: deterministic, no <random> distribution differences between libraries
    s ^= s << 13, s ^= s >> 7, s ^= s << 17;
    return static_cast<double>(s % 1000000) / 1000000.0;
  };
  for (uint32_t i = 0; i < n; ++i) {
    scene::MeshRecord m = mesh_at(kX - 5000 + 10000 * next(), kY - 5000 + 10000 * next(), 40 * next());
    const auto size = static_cast<float>(1 + 30 * next());
    for (int a = 0; a < 3; ++a) {
      m.bounds_min[a] = -size;
      m.bounds_max[a] = size;
    }
    meshes.push_back(m);
  }
  // A clump of identical meshes: the depth cap must stop the split, not loop.
  for (int i = 0; i < 100; ++i) meshes.push_back(mesh_at(kX + 1, kY + 1, 0));
  return meshes;
}

}  // namespace

TEST(BroadPhase, QuadtreeEqualsBruteForceFromManyViews) {
  const auto meshes = random_city(60000, 3);  // above kParallelMinMeshes: the TBB path runs too
  BroadPhase bp(meshes);
  EXPECT_GT(bp.node_count(), meshes.size() / BroadPhase::kLeafMeshes);
  EXPECT_LE(bp.depth(), BroadPhase::kMaxDepth);
  EXPECT_EQ(bp.mesh_count(), meshes.size());
  for (int view = 0; view < 12; ++view) {
    const CameraPose pose{
        {kX - 3000 + 500.0 * view, kY - 2000 + 300.0 * view, 20.0 + 10 * view}, 30.0 * view, -5.0 * (view % 4)};
    const Camera cam = make_camera(pose, CameraLens{60, 75, 16.0 / 9.0, 1, 4000});
    const Frustum f = Frustum::from_matrix(cam.wide_proj * cam.view);
    std::vector<uint32_t> serial, parallel;
    BroadPhaseStats stats;
    bp.query(f, cam.position, serial, &stats, false);
    bp.query(f, cam.position, parallel, nullptr, true);
    EXPECT_EQ(serial, parallel) << "view " << view;  // same order, whatever the threads did
    std::vector<uint32_t> sorted = serial;
    std::sort(sorted.begin(), sorted.end());
    EXPECT_EQ(sorted, brute_force(meshes, f, cam.position)) << "view " << view;
    // The tree must skip work: far fewer boxes tested than meshes in the city.
    EXPECT_LT(stats.nodes_tested + stats.meshes_tested, meshes.size() / 2) << "view " << view;
  }
}

TEST(BroadPhase, EmptySceneAndSingleMesh) {
  BroadPhase empty(std::span<const scene::MeshRecord>{});
  std::vector<uint32_t> out{7};
  const Camera cam = make_camera(CameraPose{{kX, kY, 0}, 0, 0}, CameraLens{});
  empty.query(Frustum::from_matrix(cam.wide_proj * cam.view), cam.position, out);
  EXPECT_TRUE(out.empty());
  EXPECT_EQ(empty.node_count(), 0u);
}
