#pragma once
// The results of one texstream-bench path invocation: every configuration that was run and what its
// per-frame log gives (path_analysis.hpp), plus the headline ratios. Written as results.json and report.md
// (path_report.cpp); the plot script reads results.json and the raw per-frame CSVs.
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "path_analysis.hpp"

namespace texstream::bench {

struct ConfigRun {
  std::string name;               // file-safe: runs/<name>/, raw/<name>.csv
  std::string group;              // "baseline", "alpha", "beta", "lockstep", "reference"
  std::string label;              // what the report calls it
  std::vector<std::string> sets;  // --set overrides on top of the common ones
  bool in_process = false;        // texstream-render-inprocess
  bool measured = true;           // compared with the reference frames
  int exit_code = -1;
  std::string failure;  // empty when the run and its analysis succeeded
  double wall_s = 0;    // the whole process, start-up and preload included
  // From the run's summary.json: bytes of streamed mips never displayed ÷ bytes streamed (NaN: unknown).
  double wasted_bytes_frac = 0;
  RunAnalysis analysis;
};

struct HeadlineRatios {
  bool lockstep_identical = false;
  std::string lockstep_difference;    // where the two lock-step runs first differ
  double max_latency_ratio = 0;       // baseline ÷ ours: max frame latency
  double popin_ratio = 0;             // baseline ÷ ours: largest frame-to-frame MSE while the camera is still
  double integrated_error_ratio = 0;  // baseline ÷ ours: Σ MSE · Δt
  double streaming_overhead = 0;      // ours ÷ all-resident: median frame latency
  double process_boundary_cost = 0;   // two-process ÷ in-process: median frame latency
  // Issue 25 (docs/design/stream_metrics.md), each baseline ÷ ours but the last two:
  double time_to_detail_ratio = 0;    // median over cuts of the deficit-based time to detail (NaN: no cuts)
  double mip_deficit_ratio = 0;       // Σ mip deficit · Δt
  double p99_latency_ratio = 0;       // p99 frame latency
  double resident_blend_psnr_db = 0;  // median PSNR of resident_blend: all resident, the default blend
  double wasted_bytes_frac = 0;       // ours: bytes of mips never displayed ÷ bytes streamed
  // Every baseline ÷ ours ratio above, one value per pair of runs (--repeat); "seed_<key>": baseline ÷ seed.
  // The scalar fields are the medians (nearest rank) of these.
  std::map<std::string, std::vector<double>> per_pair;
};

struct BenchResults {
  std::filesystem::path scene, path_file, out;
  std::filesystem::path config_file;  // --config (default: config/lavapipe.toml); empty: built-in defaults
  std::string device;
  std::string reference_mode;      // kReferencePreload or kReferenceLockstepLoad (path_runner.hpp)
  std::vector<std::string> notes;  // what the report must say besides the tables (e.g. runs skipped)
  bool quick = false;
  uint32_t width = 0, height = 0;
  double frame_time_s = 0;
  double path_duration_s = 0;
  std::vector<double> cuts_s;
  std::vector<ConfigRun> runs;
  HeadlineRatios ratios;
  double bench_wall_s = 0;
  // Context for the real-time figures: other load on the machine makes latencies noisy.
  std::string load_before, load_after;  // /proc/loadavg's 1-minute average, "?" if unreadable
  unsigned cores = 0;
  const ConfigRun* find(const std::string& name) const;
};

Status write_results_json(const BenchResults& r, const std::filesystem::path& file);
Status write_report(const BenchResults& r, const std::filesystem::path& file, bool with_plots);

}  // namespace texstream::bench
