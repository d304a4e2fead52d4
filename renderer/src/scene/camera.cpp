#include "texstream/render/scene/camera.hpp"

#include <glm/gtc/matrix_transform.hpp>

#include <cmath>

namespace texstream::render {

glm::vec3 forward_from_angles(double yaw_deg, double pitch_deg) {
  const double yaw = glm::radians(yaw_deg);
  const double pitch = glm::radians(pitch_deg);
  return glm::vec3(static_cast<float>(std::sin(yaw) * std::cos(pitch)),
                   static_cast<float>(std::cos(yaw) * std::cos(pitch)), static_cast<float>(std::sin(pitch)));
}

glm::mat4 view_rotation(const glm::vec3& forward) {
  const glm::vec3 up = std::abs(forward.z) > 0.999f ? glm::vec3(0, 1, 0) : glm::vec3(0, 0, 1);
  return glm::lookAtRH(glm::vec3(0.0f), forward, up);
}

glm::mat4 perspective_reversed_z(double fov_y_deg, double aspect, double near_m, double far_m) {
  const double t = std::tan(glm::radians(fov_y_deg) * 0.5);
  glm::mat4 p(0.0f);
  p[0][0] = static_cast<float>(1.0 / (aspect * t));
  p[1][1] = static_cast<float>(-1.0 / t);  // Vulkan clip space: y down
  // z_clip = a z_view + b, w_clip = -z_view: depth 1 at z_view = -near, 0 at z_view = -far.
  p[2][2] = static_cast<float>(near_m / (far_m - near_m));
  p[2][3] = -1.0f;
  p[3][2] = static_cast<float>(near_m * far_m / (far_m - near_m));
  return p;
}

Camera make_camera(const CameraPose& pose, const CameraLens& lens) {
  Camera c;
  c.position = {pose.position[0], pose.position[1], pose.position[2]};
  c.forward = forward_from_angles(pose.yaw_deg, pose.pitch_deg);
  c.view = view_rotation(c.forward);
  c.proj = perspective_reversed_z(lens.fov_y_deg, lens.aspect, lens.near_m, lens.far_m);
  c.wide_proj = perspective_reversed_z(lens.wide_fov_y_deg, lens.aspect, lens.near_m, lens.far_m);
  return c;
}

Frustum Frustum::from_matrix(const glm::mat4& m) {
  // Gribb-Hartmann on rows of m for Vulkan clip space: -w <= x, y <= w and 0 <= z <= w.
  auto row = [&](int r) { return glm::vec4(m[0][r], m[1][r], m[2][r], m[3][r]); };
  Frustum f;
  f.planes = {row(3) + row(0), row(3) - row(0), row(3) + row(1), row(3) - row(1), row(2), row(3) - row(2)};
  for (auto& p : f.planes) p /= glm::length(glm::vec3(p));
  return f;
}

Frustum::Side Frustum::classify(const glm::vec3& min, const glm::vec3& max) const {
  Side side = Side::kInside;
  for (const auto& p : planes) {
    // The corner farthest along the normal decides "outside"; the nearest decides "inside".
    const glm::vec3 far_corner(p.x >= 0 ? max.x : min.x, p.y >= 0 ? max.y : min.y, p.z >= 0 ? max.z : min.z);
    const glm::vec3 near_corner(p.x >= 0 ? min.x : max.x, p.y >= 0 ? min.y : max.y, p.z >= 0 ? min.z : max.z);
    if (glm::dot(glm::vec3(p), far_corner) + p.w < 0) return Side::kOutside;
    if (glm::dot(glm::vec3(p), near_corner) + p.w < 0) side = Side::kIntersects;
  }
  return side;
}

}  // namespace texstream::render
