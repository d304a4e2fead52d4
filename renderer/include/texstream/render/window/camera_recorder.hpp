#pragma once
// Records the interactive camera as a camera path (common/camera_path.hpp) so a flight found by hand can be
// replayed headless, frame for frame (issue 8's benchmarks). Key R toggles it; each recording starts at
// time 0 and writes one keyframe per rendered frame.
#include <filesystem>
#include <vector>

#include "texstream/common/camera_path.hpp"
#include "texstream/common/result.hpp"

namespace texstream::render {

class CameraRecorder {
 public:
  explicit CameraRecorder(std::filesystem::path file) : file_(std::move(file)) {}
  bool recording() const { return recording_; }
  void start();
  // Keyframe at `time_s` since the recording started (ignored while not recording; times must not decrease).
  void add(double time_s, const CameraPose& pose);
  // Writes the keyframes (at least one) to the file and stops; an empty recording writes nothing.
  Status stop();
  size_t keyframes() const { return keys_.size(); }
  const std::filesystem::path& file() const { return file_; }

 private:
  std::filesystem::path file_;
  bool recording_ = false;
  std::vector<CameraKey> keys_;
};

}  // namespace texstream::render
