#pragma once
// What texstream-bench path computes from the per-frame log of one run (render/frame_log.hpp): the seed's
// table quantities (median / average / max, seed 000 Tables 3-7), time-integrated image error and mip
// deficit, p95/p99 latency, the largest pop-in, and how fast the image recovers and gets its detail after
// each instant view switch (docs/design/stream_metrics.md). Pure: no I/O, no clock.
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

// Time to detail after a cut (issue 25; the Cesium-style "time until everything is loaded", but for what the
// view needs), two kinds, each the virtual time from the cut at `cut_s` to the first frame of the segment
// [cut_s, segment_end_s) that draws the view in detail, NaN ("never") when no frame of the segment does:
//   deficit_s  the first frame drawn with a weighted mip deficit of ~0 (≤ kDetailDeficit): frame f's
//              mip_deficit is measured on the residency at its end, which frame f + 1 draws, so deficit_s =
//              time_s(f) + frame_time_s − cut_s for the first f in the segment whose mip_deficit ≤ kDetailDeficit
//              with a visibility list read at or after the cut (list_fresh in a frame of [cut_s, f]): the
//              list of the view before the cut says nothing about the view after it.
//   psnr_s     the first frame whose PSNR is within kDetailToleranceDb of the segment's target: the settled
//              PSNR (recovery_after_cut: median PSNR over the last kSettleWindowS of the segment) standing in
//              for the reference's own, which every frame matches only up to the blending's and the
//              sampling's error. A segment still refining at its end settles low, and reaches it early.
struct TimeToDetail {
  double cut_s = 0;
  double deficit_s = 0;
  double psnr_s = 0;
  double target_psnr_db = 0;  // the settled PSNR psnr_s aims at (NaN: no PSNR in the segment)
};
// Levels, weighted mean over the view. Not exactly 0: while the camera moves after a cut, textures entering
// at the edges keep the deficit at 0.002-0.04 levels (measured, lavapipe default path), which no one sees.
inline constexpr double kDetailDeficit = 0.1;
inline constexpr double kDetailToleranceDb = 0.5;  // issue 25: "within 0.5 dB of the reference"
TimeToDetail time_to_detail(const std::vector<render::FrameRecord>& frames, double cut_s, double segment_end_s,
                            double frame_time_s);

// The median over cuts of the deficit-based time to detail, a "never" counted as +∞ (longer than any time
// reached); NaN without cuts.
double median_time_to_detail(const std::vector<TimeToDetail>& cuts);

// a ÷ b for the headline ratios (baseline ÷ ours): 1 when both are 0; a ÷ 0 = +∞; with a "never" (+∞):
// +∞ ÷ b = +∞ and a ÷ +∞ = 0; NaN when either is NaN or both are +∞ (neither got there: no comparison).
double headline_ratio(double a, double b);

// Nearest rank: the smallest value that at least fraction `q` of `values` do not exceed (NaN when empty).
double nearest_rank(std::vector<double> values, double q);

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

// Where frames spent their latency (frames.csv's parts, frame_log.hpp), mean over a set of frames, ms; mips the
// mean mips uploaded in them.
struct LatencyParts {
  uint64_t frames = 0;
  double latency = 0, plan = 0, intake = 0, bind = 0, record = 0, gpu = 0, cycle = 0, mips = 0;
};

struct RunAnalysis {
  uint64_t frames = 0;
  Stat3 latency_ms, tw_ms, load_size_mb, mip_bias, mips_per_s, mb_per_s, bound_pages, server_hit_rate;
  Stat3 mse, psnr_db, ssim;
  double integrated_mse = 0;         // Σ MSE · Δt over the run (MSE · s, Δt = virtual frame time)
  double integrated_dssim = 0;       // Σ (1 - SSIM) · Δt (s)
  double max_popin_mse = 0;          // largest frame-to-frame MSE while the camera is still
  uint64_t popin_frames = 0;         // frames where pop-in was measured (camera still)
  std::vector<Recovery> recoveries;  // one per cut inside the run
  double p95_latency_ms = 0;         // nearest rank, frame 0 excluded as for latency_ms
  double p99_latency_ms = 0;
  Stat3 mip_deficit;                  // per frame, levels (frame_log.hpp)
  double integrated_mip_deficit = 0;  // Σ mip_deficit · Δt over the frames that have one (levels · s)
  std::vector<TimeToDetail> detail;   // one per cut inside the run
  LatencyParts slowest;               // the frames at or above the p99 latency (those that make the p99)
  LatencyParts all;                   // every frame the latency statistics count
};
RunAnalysis analyse_run(const std::vector<render::FrameRecord>& frames, double frame_time_s,
                        const std::vector<double>& cuts_s);

// The per-frame columns that depend on the frame index only in lock-step mode (no wall-clock quantity):
// two runs are identical when every one of them is bit-equal in every frame. Returns "" when identical, else
// where they first differ.
std::string lockstep_difference(const std::vector<render::FrameRecord>& a, const std::vector<render::FrameRecord>& b);

}  // namespace texstream::bench
