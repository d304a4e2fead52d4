#pragma once
// Camera maths for a renderer that draws everything camera-relative: the position stays in double (map
// coordinates, ~10^6 m), the view matrix is a pure rotation and the projection is reversed-Z with Vulkan's
// [0, 1] depth and downward y. World axes: x east, y north, z up (common/camera_path.hpp).
#include <glm/glm.hpp>

#include <array>

#include "texstream/common/camera_path.hpp"

namespace texstream::render {

struct Camera {
  std::array<double, 3> position{};  // map coordinates
  glm::vec3 forward{0, 1, 0};        // unit view direction
  glm::mat4 view{1.0f};              // rotation only
  glm::mat4 proj{1.0f};              // viewport FOV
  glm::mat4 wide_proj{1.0f};         // wider off-screen FOV (seed 000 §3.2)
};

struct CameraLens {
  double fov_y_deg = 60;
  double wide_fov_y_deg = 75;
  double aspect = 16.0 / 9.0;
  double near_m = 1;
  double far_m = 20000;
};

// yaw 0 looks along +y, 90 along +x; pitch positive upward.
glm::vec3 forward_from_angles(double yaw_deg, double pitch_deg);
// Right-handed look-along rotation with z up (y up when looking almost straight up or down).
glm::mat4 view_rotation(const glm::vec3& forward);
// Reversed-Z perspective: depth 1 at the near plane, 0 at the far plane; clip y points down (Vulkan).
glm::mat4 perspective_reversed_z(double fov_y_deg, double aspect, double near_m, double far_m);
Camera make_camera(const CameraPose& pose, const CameraLens& lens);

// Six planes (xyz = inward normal, w = distance) of the frustum of `view_proj`, in camera-relative space.
struct Frustum {
  std::array<glm::vec4, 6> planes;
  static Frustum from_matrix(const glm::mat4& view_proj);
  enum class Side { kOutside, kIntersects, kInside };
  // Box given relative to the camera.
  Side classify(const glm::vec3& min, const glm::vec3& max) const;
};

}  // namespace texstream::render
