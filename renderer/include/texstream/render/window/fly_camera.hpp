#pragma once
// The interactive mode's camera (render.window = true): mouse turns, WASD moves along the view, Q/E (or
// Space/C) move down/up, Shift moves faster. Pure maths on a CameraPose (map coordinates in double), so it is
// unit-tested without a window and the pose feeds the same camera code as a camera path.
#include "texstream/common/camera_path.hpp"

namespace texstream::render {

struct FlyInput {
  bool forward = false, back = false, left = false, right = false, up = false, down = false, fast = false;
  double mouse_dx_px = 0;  // cursor motion since the last frame (only while the mouse button is held)
  double mouse_dy_px = 0;
};

class FlyCamera {
 public:
  // 30 m/s is a brisk drone over a city block; Shift x8 crosses a district in seconds.
  static constexpr double kSpeedMps = 30;
  static constexpr double kFastFactor = 8;
  static constexpr double kDegreesPerPixel = 0.15;
  // Looking straight up or down makes yaw meaningless (gimbal lock): stop just short of it.
  static constexpr double kMaxPitchDeg = 89;

  explicit FlyCamera(const CameraPose& start) : pose_(start) {}
  // Advances by `dt_s` seconds of input; a non-finite or negative dt moves nothing.
  void update(const FlyInput& input, double dt_s);
  const CameraPose& pose() const { return pose_; }

 private:
  CameraPose pose_;
};

}  // namespace texstream::render
