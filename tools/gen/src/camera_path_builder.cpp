#include "camera_path_builder.hpp"

#include <cmath>
#include <limits>
#include <vector>

namespace texstream::gen {

namespace {

constexpr double kPauseS = 2.0;  // seed 000 §4.1: pauses of 2 s

// A straight flight: from `start` (city-local x, y) along `yaw_deg` at `speed` for `duration` seconds.
struct Flight {
  double x, y;
  double yaw_deg;
  double altitude_m;  // above street level; 30-120 m keeps facades and roofs close in view
  double pitch_deg;   // negative: looking down
  double speed_mps;
  double duration_s;
  double climb_mps = 0;
};

class PathWriter {
 public:
  explicit PathWriter(const double origin[3]) : origin_{origin[0], origin[1], origin[2]} {}

  // Appends the flight starting at the current time, then holds its last pose for a pause.
  void fly(const Flight& f, bool pause_after) {
    const double rad = f.yaw_deg * 3.14159265358979323846 / 180.0;
    const double dist = f.speed_mps * f.duration_s;
    add(t_, f.x, f.y, f.altitude_m, f.yaw_deg, f.pitch_deg);
    t_ += f.duration_s;
    const double ex = f.x + std::sin(rad) * dist, ey = f.y + std::cos(rad) * dist;
    const double ez = f.altitude_m + f.climb_mps * f.duration_s;
    add(t_, ex, ey, ez, f.yaw_deg, f.pitch_deg);
    if (pause_after) {
      t_ += kPauseS;
      add(t_, ex, ey, ez, f.yaw_deg, f.pitch_deg);
    }
  }

  CameraPath take() { return CameraPath(std::move(keys_)); }

 private:
  void add(double t, double x, double y, double alt, double yaw, double pitch) {
    keys_.push_back(CameraKey{t, CameraPose{{origin_[0] + x, origin_[1] + y, origin_[2] + alt}, yaw, pitch}});
  }

  double origin_[3];
  double t_ = 0;
  std::vector<CameraKey> keys_;
};

// The block whose density is closest to `target` among those at least `min_r` cells from the centre
// (falls back to all blocks when none is that far out: small cities).
const Block& pick_block(const CityLayout& city, float target, double min_r) {
  const Block* best = &city.blocks.front();
  double best_score = std::numeric_limits<double>::max();
  for (int pass = 0; pass < 2 && best_score == std::numeric_limits<double>::max(); ++pass)
    for (const Block& b : city.blocks) {
      if (pass == 0 && std::hypot(b.i, b.j) < min_r) continue;
      const double score = std::fabs(b.density - target);
      if (score < best_score) {
        best_score = score;
        best = &b;
      }
    }
  return *best;
}

}  // namespace

CameraPath build_default_camera_path(const CityLayout& city, const double origin[3]) {
  const double p = city.block_pitch_m;
  double max_r = 0;
  for (const Block& b : city.blocks) max_r = std::max(max_r, std::hypot(b.i, b.j));
  PathWriter w(origin);

  // 1. 0-8 s: low along the street east of the centre block, looking north at the densest facades, so the
  //    first seconds (what a short demo renders) are full of nearby buildings.
  w.fly({0.5 * p, -1.0 * p, 0.0, 40.0, -22.0, 14.0, 8.0}, true);
  // 2. cut: the sparse outskirts, along a street heading east, a little higher.
  const Block& sparse = pick_block(city, 0.1f, 0.7 * max_r);
  w.fly({(sparse.i - 0.9) * p, (sparse.j - 0.5) * p, 90.0, 60.0, -30.0, 16.0, 8.0}, true);
  // 3. cut: a medium-density district, heading north.
  const Block& medium = pick_block(city, 0.5f, 0.4 * max_r);
  w.fly({(medium.i - 0.5) * p, (medium.j - 0.9) * p, 0.0, 80.0, -28.0, 18.0, 8.0}, true);
  // 4. cut: high over the centre, diagonally across blocks.
  //    120 m clears the tallest towers (24 storeys of <= 4 m plus a 4-storey tier: ~117 m).
  w.fly({-1.0 * p, -1.0 * p, 45.0, 120.0, -35.0, 20.0, 8.0}, true);
  // 5. cut: a long flight from the centre outwards along a street heading west, climbing slowly.
  w.fly({0.3 * p, -0.5 * p, 270.0, 70.0, -25.0, 25.0, 12.0, 2.5}, false);
  return w.take();
}

}  // namespace texstream::gen
