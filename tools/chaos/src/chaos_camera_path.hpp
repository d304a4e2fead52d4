#pragma once
// Camera paths for a chaos run, built from the scene's own fly-through: the path repeated (a cut between
// loops) for the kill phase, then the final pose held still for a convergence tail; and the reference path,
// which is only that final pose held (the converged image depends on the final pose alone).
#include "texstream/common/camera_path.hpp"

namespace texstream::chaos {

// `loops` copies of `scene_path` back to back, then its final pose held for `hold_s` seconds.
CameraPath looping_path(const CameraPath& scene_path, int loops, double hold_s);
// The final pose of `scene_path` held for `hold_s` seconds.
CameraPath hold_path(const CameraPath& scene_path, double hold_s);

}  // namespace texstream::chaos
