#pragma once
// Seed 002 Fig. 12 redone on our city (issue 4, phase "fig12" of texstream-bench storage): time-integrated
// image error of a fixed camera path when texstream-render's server reads the scene from an http origin
// (nginx on loopback) over links of different speed. A reference run (render.preload_all, local storage)
// gives the ground truth; each link is a real-time texstream-render run (config/lavapipe.toml, paced frames)
// whose frames.csv the path bench's analysis turns into ∫MSE dt and mean PSNR (path_analysis.hpp).
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace texstream::bench {

struct Fig12Link {
  std::string name;
  double nominal_bytes_s = 0;  // 0: unlimited
};

struct Fig12Plan {
  bool quick = false;
  std::filesystem::path scene;   // scene.dir (nginx serves the same folder)
  std::filesystem::path work;    // run folders, reference frames (the caller removes it)
  std::filesystem::path out;     // storage_fig12.csv, storage_fig12_frames.csv
  std::filesystem::path config;  // the renderer's profile (config/lavapipe.toml)
  std::string origin_url;        // nginx's unthrottled prefix: the cap comes from storage.slow_bandwidth_mb_s
  std::vector<Fig12Link> links;
};

struct Fig12Row {
  Fig12Link link;
  std::string failure;  // empty: the run and its analysis succeeded
  uint64_t frames = 0;
  double integrated_mse = 0;  // Σ MSE · Δt over the path (MSE · s, virtual time)
  double mean_psnr_db = 0;
  double wall_s = 0;  // frame 0 start to last frame end
  uint64_t bytes = 0, mips = 0;
  double mb_s = 0, mips_s = 0;  // delivered to the renderer, per wall second of the path
  double first_mip_ms = 0;      // wall time from frame 0 to the end of the first frame that received a mip (NaN: none)
};

struct Fig12Result {
  std::string failure;  // set when nothing could be measured (no scene, no reference)
  uint32_t width = 0, height = 0;
  double path_s = 0;
  uint64_t reference_frames = 0;
  std::vector<Fig12Row> rows;
  const Fig12Row* find(const std::string& name) const;
};

// Runs the reference and one renderer per link; writes <out>/storage_fig12.csv (one row per link) and
// <out>/storage_fig12_frames.csv (per frame and link: the error over time). Never throws; failures are in
// the result.
Fig12Result run_fig12(const Fig12Plan& plan);

}  // namespace texstream::bench
