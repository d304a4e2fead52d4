// Broad phase: frustum maths and the grid query at map coordinates.
#include <gtest/gtest.h>

#include <algorithm>

#include "texstream/render/broad_phase.hpp"
#include "texstream/render/camera.hpp"

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
  meshes.push_back(mesh_at(kX, kY + 50, 0));        // 0: ahead
  meshes.push_back(mesh_at(kX, kY - 50, 0));        // 1: behind
  meshes.push_back(mesh_at(kX + 500, kY + 10, 0));  // 2: far to the right
  meshes.push_back(mesh_at(kX + 5, kY + 300, 0));   // 3: ahead, slightly right
  meshes.push_back(mesh_at(kX, kY + 30000, 0));     // 4: beyond the far plane
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
