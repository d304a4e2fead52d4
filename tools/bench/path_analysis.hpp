#pragma once
// What texstream-bench path computes from the per-frame log of one run (render/frame_log.hpp): the seed's
// table quantities (median / average / max, seed 000 Tables 3-7), time-integrated image error, the largest
// pop-in, and how fast the image recovers after each instant view switch. Pure: no I/O, no clock.
#include <cstdint>
#include <string>
#include <vector>

#include "texstream/common/camera_path.hpp"
#include "texstream/render/measure/frame_log.hpp"

namespace texstream::bench {

struct Stat3 {
  double median = 0, avg = 0, max = 0;
  uint64_t samples = 0;  // finite values it was computed from (0: all three are NaN)
};
// NaN entries (not measured) are skipped.
Stat3 stat3(const std::vector<double>& values);

// Seed 000 §4.2 samples its transfer rates every 0.10423 s; frames are grouped into windows of at least
// this much wall time and each window's mips and bytes are divided by its duration.
inline constexpr double kRateWindowS = 0.10423;
struct Rates {
  std::vector<double> mips_per_s;
  std::vector<double> mb_per_s;  // 10^6 bytes
};
Rates windowed_rates(const std::vector<render::FrameRecord>& frames, double window_s = kRateWindowS);

// Recovery after an instant view switch (a cut of the camera path at `cut_s`): the settled PSNR is the median
// PSNR over the last `settle_window_s` of virtual time before the segment ends (the next cut or the end of the
// run): by then the view has had its pause to refine. The recovery time is the virtual time from the cut to
// the first frame whose PSNR is within `tolerance_db` of it (NaN when never reached, or no frames).
struct Recovery {
  double cut_s = 0;
  double settled_psnr_db = 0;
  double seconds = 0;
};
inline constexpr double kRecoveryToleranceDb = 1.0;  // issue 8: "within 1 dB of the settled PSNR"
inline constexpr double kSettleWindowS = 0.5;
Recovery recovery_after_cut(const std::vector<render::FrameRecord>& frames, double cut_s, double segment_end_s,
                            double tolerance_db = kRecoveryToleranceDb, double settle_window_s = kSettleWindowS);

// Times of the instant switches of a path: keyframes that repeat the previous keyframe's time with a
// different pose (camera_path.hpp). Times in the path's own clock.
std::vector<double> cut_times(const CameraPath& path);

// The part of `path` between t0 and t1, re-timed to start at 0: the keyframes strictly inside, the poses
// sampled at both ends, and both keyframes of a cut inside the range. Fails nothing: an empty or reversed
// range gives a one-pose path of duration 0.
CameraPath path_section(const CameraPath& path, double t0, double t1);

// Frame 0 carries one-time costs that every configuration pays alike and that have nothing to do with
// streaming (the first submission, first use of each pipeline in the driver): it is left out of the latency
// and t_w statistics (only those). Measured on lavapipe: frame 0 takes 40-420 ms, the next ones 10-50 ms.
inline constexpr uint64_t kWarmUpFrames = 1;

struct RunAnalysis {
  uint64_t frames = 0;
  Stat3 latency_ms, tw_ms, load_size_mb, mip_bias, mips_per_s, mb_per_s, bound_pages, server_hit_rate;
  Stat3 mse, psnr_db, ssim;
  double integrated_mse = 0;         // Σ MSE · Δt over the run (MSE · s, Δt = virtual frame time)
  double integrated_dssim = 0;       // Σ (1 - SSIM) · Δt (s)
  double max_popin_mse = 0;          // largest frame-to-frame MSE while the camera is still
  uint64_t popin_frames = 0;         // frames where pop-in was measured (camera still)
  std::vector<Recovery> recoveries;  // one per cut inside the run
  double p95_latency_ms = 0;
};
RunAnalysis analyse_run(const std::vector<render::FrameRecord>& frames, double frame_time_s,
                        const std::vector<double>& cuts_s);

// The per-frame columns that depend on the frame index only in lock-step mode (no wall-clock quantity):
// two runs are identical when every one of them is bit-equal in every frame. Returns "" when identical, else
// where they first differ.
std::string lockstep_difference(const std::vector<render::FrameRecord>& a, const std::vector<render::FrameRecord>& b);

}  // namespace texstream::bench
