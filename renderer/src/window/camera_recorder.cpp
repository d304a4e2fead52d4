#include "texstream/render/window/camera_recorder.hpp"

#include <fstream>

namespace texstream::render {

void CameraRecorder::start() {
  keys_.clear();
  recording_ = true;
}

void CameraRecorder::add(double time_s, const CameraPose& pose) {
  if (!recording_) return;
  if (!keys_.empty() && time_s < keys_.back().time_s) time_s = keys_.back().time_s;  // never backwards
  keys_.push_back(CameraKey{time_s, pose});
}

Status CameraRecorder::stop() {
  recording_ = false;
  if (keys_.empty()) return ok_status();
  const std::string text = CameraPath(keys_).to_text();
  std::error_code ec;
  if (file_.has_parent_path()) std::filesystem::create_directories(file_.parent_path(), ec);
  std::ofstream out(file_, std::ios::trunc);
  out << text;
  out.close();
  if (!out) return make_error(ErrorCode::kIo, "camera recording: cannot write '" + file_.string() + "'");
  return ok_status();
}

}  // namespace texstream::render
