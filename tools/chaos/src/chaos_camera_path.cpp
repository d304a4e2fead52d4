#include "chaos_camera_path.hpp"

#include "texstream/common/contract.hpp"

namespace texstream::chaos {

CameraPath looping_path(const CameraPath& scene_path, int loops, double hold_s) {
  const auto& keys = scene_path.keys();
  TS_ASSERT(!keys.empty() && loops >= 1, "looping_path needs keys and at least one loop");
  const double period = scene_path.duration_s();
  std::vector<CameraKey> out;
  for (int l = 0; l < loops; ++l) {
    for (CameraKey k : keys) {
      // The first key of a loop has the same time as the last of the previous one: a cut.
      k.time_s += period * l;
      out.push_back(k);
    }
  }
  CameraKey last = out.back();
  last.time_s += hold_s;
  out.push_back(last);
  return CameraPath(std::move(out));
}

CameraPath hold_path(const CameraPath& scene_path, double hold_s) {
  const auto& keys = scene_path.keys();
  TS_ASSERT(!keys.empty(), "hold_path needs keys");
  CameraKey first = keys.back();
  first.time_s = 0.0;
  CameraKey last = first;
  last.time_s = hold_s;
  return CameraPath({first, last});
}

}  // namespace texstream::chaos
