#include "texstream/render/window/fly_camera.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace texstream::render {

void FlyCamera::update(const FlyInput& in, double dt_s) {
  if (std::isfinite(in.mouse_dx_px) && std::isfinite(in.mouse_dy_px)) {
    // Mouse right turns right (yaw grows clockwise seen from above: 0 north, 90 east); mouse down looks down.
    pose_.yaw_deg = std::fmod(pose_.yaw_deg + in.mouse_dx_px * kDegreesPerPixel, 360.0);
    if (pose_.yaw_deg < 0) pose_.yaw_deg += 360.0;
    pose_.pitch_deg = std::clamp(pose_.pitch_deg - in.mouse_dy_px * kDegreesPerPixel, -kMaxPitchDeg, kMaxPitchDeg);
  }
  if (!std::isfinite(dt_s) || dt_s <= 0) return;
  const double yaw = pose_.yaw_deg * std::numbers::pi / 180.0;
  const double pitch = pose_.pitch_deg * std::numbers::pi / 180.0;
  // Same axes as camera.cpp's forward_from_angles: x east, y north, z up.
  const double forward[3] = {std::sin(yaw) * std::cos(pitch), std::cos(yaw) * std::cos(pitch), std::sin(pitch)};
  const double right[3] = {std::cos(yaw), -std::sin(yaw), 0.0};
  const double f = (in.forward ? 1.0 : 0.0) - (in.back ? 1.0 : 0.0);
  const double r = (in.right ? 1.0 : 0.0) - (in.left ? 1.0 : 0.0);
  const double u = (in.up ? 1.0 : 0.0) - (in.down ? 1.0 : 0.0);
  const double step = kSpeedMps * (in.fast ? kFastFactor : 1.0) * dt_s;
  for (int a = 0; a < 3; ++a) pose_.position[a] += step * (f * forward[a] + r * right[a] + (a == 2 ? u : 0.0));
}

}  // namespace texstream::render
