#pragma once
// The default fly-through written with every generated scene (seed 000 §4.1): a bird's-eye flight at low
// altitude over dense and sparse parts of the city with 4 pauses of 2 s and 4 instant switches to new views.
#include "city_layout.hpp"
#include "texstream/common/camera_path.hpp"

namespace texstream::gen {

// `origin` is the map coordinate of the city's local (0, 0, 0) (street level at the centre).
CameraPath build_default_camera_path(const CityLayout& layout, const double origin[3]);

}  // namespace texstream::gen
