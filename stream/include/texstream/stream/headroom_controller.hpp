#pragma once
// The default streaming controller (controller.mode = auto): the load size s and mip bias b of the next
// streaming cycle from measured frame latencies, with a target it sets itself. docs/controller.md gives the
// measurements behind each term; the seed's Eq. 4-7 stay as controller.mode = seed.
//
//   target  T = max(2 f, T_min), f = the frame latency without streaming work, estimated from the last
//           kWindow frames as min_i(Δt_i − k·bytes_i − c·mips_i) with k and c the costs of an uploaded byte
//           and of an uploaded mip, fitted jointly (non-negative least squares) over the same window (seed 000 §4.3: "α
//           about twice the latency without streaming"). A user's controller.target_ms caps T, but never below 1.25 f:
//           a renderer slower than the cap is not pinned at s_min (the seed's limitation, issue 25).
//   s       starts at s_max; is cut by (T / Δt)^4 when this frame's Δt > T, and to s_min at Δt >= 2 T; grows up
//           to ×4 per frame while Δt is below the line f + 0.75 (T − f) (×4 at f, ×1 at the line; gently while
//           Eq. 5's t_w still remembers a spike above the line); holds in between. s stays below the model's
//           budget (line − f) / k: where uploads cost frame time a pause does not bank a full-size burst for
//           the next cut. k counts only when uploads explain the latencies (correlation >= 0.5), else 0.
//   b       β · smoothstep(1, 2, t_b / T), t_b = the mean of the last 5 latencies: no bias unless the latency
//           stays above the target for several frames even after s was cut.
//   pace    the mips one frame may take in: B / c, B = min(share · f, line − f). A frame's mips cost time even
//           when their bytes do not (sparse binds, copy regions, bookkeeping: ~10 µs a mip on an H200, issue
//           25), and a cut brings hundreds at once; pacing spreads them over frames so that a frame with
//           streaming stays within about (1 + share) f, the seed's "α about twice the latency without
//           streaming". No cap until c is known; never below kPaceMinMips. share = 0 (controller.pace_share)
//           turns pacing off.
//   The first frame (start-up: pipelines, first geometry) is not streaming and is left out of all of it.
//
// Pure (no clock, no I/O), deterministic, single owner. Inputs that are NaN, infinite, negative or absurd
// are rejected by the caller (AdaptiveController::on_frame) before they reach it.
#include <array>
#include <cstddef>
#include <cstdint>

namespace texstream::stream {

struct HeadroomParams {
  double s_min_bytes = 0.065e6;
  double s_max_bytes = 64e6;
  double beta = 8;
  double target_min_s = 1.0 / 60.0;  // controller.target_min_ms: a frame inside one 60 Hz refresh is no stutter
  double target_cap_s = 0;           // controller.target_ms: 0 = no cap
  double pace_share = 1.0;           // controller.pace_share: a frame's streaming work <= share · f (0: off)
};

class HeadroomController {
 public:
  static constexpr size_t kWindow = 64;                      // frames in the plant estimate (~1 s at 60 Hz)
  static constexpr size_t kMinFitFrames = 8;                 // fewer: no slope, f = the window's minimum
  static constexpr double kTargetFactor = 2.0;               // T = 2 f (seed 000 §4.3)
  static constexpr double kCapHeadroom = 1.25;               // a cap never brings T below 1.25 f
  static constexpr double kFloorShare = 0.5;                 // f >= half the quickest frame (a bad slope's limit)
  static constexpr double kGrowBelow = 0.75;                 // s grows while t_w < f + 0.75 (T - f)
  static constexpr double kMinSpreadMb = 0.5;                // k is refitted only when the window's uploads span this
  static constexpr double kMinCorrelation = 0.5;             // and k > 0 only when uploads explain the latencies
  static constexpr double kGrowthDoublings = 2.0;            // s ×4 per frame at full room
  static constexpr size_t kBiasFrames = 5;                   // b from the mean of the last 5 latencies
  static constexpr double kStutterRatio = 2.0;               // t_w >= 2 T: s = s_min at once
  static constexpr double kBiasFrom = 1.0, kBiasFull = 2.0;  // t_b / T where b starts and reaches β
  static constexpr double kMinTargetS = 1e-6;                // T never 0 (a ratio's denominator)
  static constexpr double kBytesPerUnit = 1e6;               // the fit works in MB (keeps its sums small)
  static constexpr double kPaceMinMips = 64;                 // the pace never goes below this many mips a frame
  static constexpr double kPaceSpreadMips = 64;              // c is refitted only when the window's mips span this
  static constexpr double kNoPace = 1e9;                     // "no cap" (c unknown, or pacing off)

  struct State {
    double f_s = 0;                    // frame latency without streaming work (estimate)
    double k_s_per_mb = 0;             // latency per uploaded MB (least squares over the window, >= 0)
    double budget_bytes = 0;           // (growth line - f) / k: the upload one frame has room for; s_max when k = 0
    double c_s_per_mip = 0;            // latency per uploaded mip beyond its bytes' (least squares with k, >= 0)
    double pace_mips = kNoPace;        // mips the next frame may take in
    double target_s = 0;               // T
    double s_bytes = 0;                // load size
    double b = 0;                      // mip bias
    double t_b_s = 0;                  // mean of the last kBiasFrames latencies
    double t_w_s = 0;                  // Eq. 5's weighted maximum latency, from the first frame after start-up
    bool started = false;              // the first (start-up) frame has been seen
    std::array<double, kWindow> dt{};  // the last frames: latency (s) and bytes uploaded (MB)
    std::array<double, kWindow> mb{};
    std::array<double, kWindow> mips{};
    size_t next = 0;
    size_t count = 0;
    bool operator==(const State&) const = default;
  };

  explicit HeadroomController(const HeadroomParams& p);

  // One accepted frame: its latency Δt (s), the bytes and the number of mips uploaded in it. Contract: all
  // finite and >= 0. The first frame only marks the start.
  void on_frame(double dt_s, double bytes, double mips = 0);

  double load_size_bytes() const { return state_.s_bytes; }
  double mip_bias() const { return state_.b; }
  double pace_mips() const { return state_.pace_mips; }
  double target_s() const { return state_.target_s; }
  const State& state() const { return state_; }
  const HeadroomParams& params() const { return params_; }

  // ---- the terms, exposed for tests and docs ----
  // T from f and the parameters.
  static double target(double f_s, const HeadroomParams& p);
  // The factor s is multiplied by for a frame: growth, hold (1) or cut.
  static double load_factor(double t_w_s, double dt_s, double f_s, double target_s);
  // b from the mean of the last latencies and T.
  static double bias(double beta, double t_b_s, double target_s);

 private:
  void fit();       // f, k and c from the window
  void fit_pace();  // the pace from f, c and T

  HeadroomParams params_;
  State state_;
};

}  // namespace texstream::stream
