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
