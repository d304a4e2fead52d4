#pragma once
// A camera path file: one keyframe per line, `time_s x y z yaw_deg pitch_deg`, '#' starts a comment.
// Positions are map coordinates (metres, double). yaw 0 looks along +y (north), 90 along +x (east); pitch
// is positive upward. Between keyframes the pose is interpolated linearly (yaw along the shorter arc).
// Two keyframes with the same time make an instant switch (a cut, seed 000 §4.1); a keyframe repeated at a
// later time makes a pause.
#include <filesystem>
#include <string>
#include <vector>

#include "texstream/common/result.hpp"

namespace texstream {

struct CameraPose {
  double position[3];
  double yaw_deg;
  double pitch_deg;
};

// Bit-equal poses: the camera did not move (a pause of the path, a still window).
inline bool same_pose(const CameraPose& a, const CameraPose& b) {
  return a.position[0] == b.position[0] && a.position[1] == b.position[1] && a.position[2] == b.position[2] &&
         a.yaw_deg == b.yaw_deg && a.pitch_deg == b.pitch_deg;
}

struct CameraKey {
  double time_s;
  CameraPose pose;
};

class CameraPath {
 public:
  static Result<CameraPath> load(const std::filesystem::path& file);
  static Result<CameraPath> parse(const std::string& text, const std::string& what);
  std::string to_text() const;

  explicit CameraPath(std::vector<CameraKey> keys) : keys_(std::move(keys)) {}
  double duration_s() const { return keys_.empty() ? 0.0 : keys_.back().time_s; }
  CameraPose sample(double time_s) const;
  const std::vector<CameraKey>& keys() const { return keys_; }

 private:
  std::vector<CameraKey> keys_;
};

}  // namespace texstream
