#pragma once
// The streaming controller. Mode seed is seed 000 §3.4 (Eq. 4-7, Table 2); mode auto (the default) is
// headroom_controller.hpp, which takes Eq. 5's t_w and Eq. 7's t_b from here. From one measured frame latency Δt
// per frame it derives the load size s (the bytes one streaming cycle may request, Algorithm 1's
// `loadedBatchSize > s` test) and the mip bias b (levels coarser than the visibility metadata asks for,
// Algorithm 1's `mipLevelSampled + b < mipLevel` test).
//
// UNITS. Inside the equations every latency is in SECONDS: Δt, t_w, d, t_m, t_wa, t_b, t_bl, t_bu, x and α.
// The constants of Eq. 4 (10, 30, 50 in P) and Eq. 5 (30 in the decay) make sense in that unit only: with x
// in seconds the terms of P reach 1 at |x| = 100, 33 and 20 ms — frame-latency scales — and with Δt in seconds
// the load factor moves ~0.1 per second for a 10 ms deviation (Table 3: s stays near 1 MB of a 64 MB s_max,
// max 3.3 MB). In milliseconds P(1 ms) ≈ 6·10^6 would make l jump between 0 and 1 every frame and
// (30d)^2·Δt would erase any spike in one frame, contradicting Table 3's t_w average (12.3 ms) sitting twice
// above the frame latency average (6.5 ms). docs/controller.md has the full argument. Load sizes are bytes
// (MB = 10^6 bytes as in Table 2), b is in mip levels, l is a fraction.
//
// Pure: no clock, no I/O, no Vulkan; the caller measures Δt. Deterministic: equal inputs give equal outputs.
// Robust: a Δt that is NaN, ±inf, negative or above kMaxFrameLatencyS is rejected (state unchanged, counted);
// whatever it is fed, s ∈ [s_min, s_max], b ∈ [0, β], l ∈ [0, 1] and every output is finite. Single owner.
//
// Windowed averages never drift: the 200-sample t_wa and 5-sample t_b windows keep their samples as integer
// femtoseconds with an exact integer running sum (a double running sum keeps the rounding residue of every
// sample that passes through it, e.g. of a 10 s spike among 1 µs frames); the 40-sample t_bl/t_bu edges depend on the
// current t_w through min/max and are recomputed from their window every frame anyway.
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"
#include "texstream/stream/headroom_controller.hpp"

namespace texstream::stream {

// ControllerMode is the controller.mode key's enum, in config.hpp; its names come from config_choice.hpp.

// Parameters in the controller's units (seconds, bytes, levels). Built from [controller] by from_config.
struct ControllerParams {
  ControllerMode mode = ControllerMode::kAuto;
  double alpha_s = 0.016;          // α, Table 2: 16 ms (mode seed)
  double beta = 8;                 // β, Table 2
  double s_min_bytes = 0.065e6;    // Table 2: 0.065 MB, one 64 KiB sparse block
  double s_max_bytes = 64e6;       // Table 2: 64 MB
  double fixed_load_bytes = 16e6;  // mode = fixed
  double fixed_bias = 0;           // mode = fixed
  double target_min_s = 1.0 / 60;  // mode = auto: the target is never below this
  double target_cap_s = 0;         // mode = auto: the target's cap (0: none)
  double pace_share = 1.0;         // mode = auto: a frame's streaming work <= share · f (0: no pacing)

  // Converts ms → s and MB → bytes; errors name the [controller] key.
  static Result<ControllerParams> from_config(const ControllerConfig& config);
  // Relations the equations need (finite, positive, s_min <= s_max, fixed values inside the ranges).
  Status validate() const;
};

// Exact windowed sum of the last N samples. Each sample is kept as integer femtoseconds (rounded: 0.5 fs is
// far below anything measurable, and far below the rounding a double running sum accumulates) and the sum is
// an exact 128-bit integer, so no amount of pushing makes it drift.
template <size_t N>
class LatencyWindow {
 public:
  static_assert(N > 0);
  static constexpr double kFemtosPerSecond = 1e15;

  // contract: 0 <= seconds <= AdaptiveController::kMaxFrameLatencyS (3.6e18 fs: fits int64).
  void push(double seconds);
  size_t count() const { return count_; }
  // Mean of the samples held; 0 when empty.
  double mean_s() const;
  __int128 sum_fs() const { return sum_fs_; }
  // The i-th newest sample in femtoseconds (i = 0: the last pushed); contract: i < count().
  int64_t newest_fs(size_t i) const { return values_[(next_ + N - 1 - i) % N]; }
  bool operator==(const LatencyWindow&) const = default;

 private:
  std::array<int64_t, N> values_{};
  size_t next_ = 0;
  size_t count_ = 0;
  __int128 sum_fs_ = 0;
};

// The history of the Eq. 7 edges: the last N values of t_bl (or t_bu), in seconds.
template <size_t N>
struct EdgeHistory {
  std::array<double, N> values{};
  size_t next = 0;
  size_t count = 0;
  void push(double v) {
    values[next] = v;
    next = (next + 1) % N;
    if (count < N) ++count;
  }
  bool operator==(const EdgeHistory&) const = default;
};

class AdaptiveController {
 public:
  // Window lengths of seed 000 Eq. 6 and 7.
  static constexpr size_t kTwaSamples = 200;  // t_wa: "200 previous samples of t_w" (~2 s)
  static constexpr size_t kEdgeSamples = 40;  // t_bl, t_bu: "40 samples ... one-third of the frames in a second"
  static constexpr size_t kTbSamples = 5;     // t_b: "5 previous weighted maximum frame latency t_w"
  // A frame latency above an hour is a clock error, not a stutter; it is rejected like NaN. It also bounds
  // a window sample: 3600 s = 3.6·10^18 fs < 2^63.
  static constexpr double kMaxFrameLatencyS = 3600.0;
  // Bytes uploaded in one frame above an exabyte are a counter error; rejected like a bad latency.
  static constexpr double kMaxFrameBytes = 1e18;
  // Mips uploaded in one frame above 10^12 are a counter error; rejected like a bad latency.
  static constexpr double kMaxFrameMips = 1e12;

  // The controller's state after the last accepted frame (all latencies in seconds).
  struct State {
    double t_w = 0;      // Eq. 5 weighted maximum frame latency (0 before the first frame)
    double l = 0;        // Eq. 4 load factor; starts at 0: streaming ramps up from s_min, never starts with a burst
    double x = 0;        // Eq. 4 t_w - t_m of the last frame
    double t_wa = 0;     // Eq. 6 mean of the previous 200 t_w used by the last frame
    double t_m = 0;      // Eq. 6 threshold of the last frame
    double t_b = 0;      // Eq. 7 mean of the previous 5 t_w
    double t_bl = 0;     // Eq. 7 lower edge
    double t_bu = 0;     // Eq. 7 upper edge
    double s_bytes = 0;  // Eq. 4 load size
    double b = 0;        // Eq. 7 mip bias
    LatencyWindow<kTwaSamples> twa_window;
    LatencyWindow<kTbSamples> tb_window;
    EdgeHistory<kEdgeSamples> bl_history;
    EdgeHistory<kEdgeSamples> bu_history;
    bool operator==(const State&) const = default;
  };

  static Result<AdaptiveController> create(const ControllerParams& params);

  // One frame: Δt in seconds, the bytes and the number of mips uploaded during it (mode auto uses them to
  // tell the frame's streaming work from its rendering; the seed's equations ignore them). Returns false (and
  // changes nothing but the rejected counter) for NaN, ±inf, negative or absurd (> kMaxFrameLatencyS, >
  // kMaxFrameBytes, > kMaxFrameMips) input. 0 and denormals are accepted (a frame can be that fast only on a
  // broken clock, but they are numbers the equations handle).
  bool on_frame(double frame_latency_s, double uploaded_bytes = 0, double uploaded_mips = 0);

  // Outputs for the next streaming cycle: mode auto's (headroom_controller.hpp), mode seed's (Eq. 4-7), or
  // constant in mode none/fixed. The seed's state follows Eq. 4-7 in every mode (so a baseline run can still
  // report t_w as the seed's Tables do, and mode auto takes its t_w and t_b).
  double load_size_bytes() const;
  uint64_t load_bytes() const;  // load_size_bytes() rounded down, for byte counters
  double mip_bias() const;
  // The most mips the next frame should take in: mode auto's pace (headroom_controller.hpp), else no limit
  // (HeadroomController::kNoPace).
  double pace_mips() const;
  double load_factor() const { return state_.l; }
  double weighted_latency_s() const { return state_.t_w; }
  const State& state() const { return state_; }  // the seed's (Eq. 4-7)
  const HeadroomController& headroom() const { return headroom_; }
  // The latency the controller aims at: T in mode auto, α in mode seed, 0 in none/fixed.
  double target_s() const;
  const ControllerParams& params() const { return params_; }
  uint64_t frames_accepted() const { return accepted_; }
  uint64_t frames_rejected() const { return rejected_; }

  // ---- the equations, exposed so tests and docs can evaluate them alone (seconds throughout) ----
  // Eq. 4's polynomial P(|x|) = |x| + (10|x|)^2 + (30|x|)^3 + (50|x|)^4.
  static double load_polynomial(double x);
  // Eq. 4's step of l before clamping: sign(-x) · P · Δt.
  static double load_factor_step(double x, double dt);
  // Eq. 5: t_w from the previous t_w and this frame's Δt.
  static double weighted_latency(double t_w_prev, double dt);
  // Eq. 6: t_m from t_wa and α.
  static double threshold(double t_wa, double alpha);
  // GLSL smoothstep (Hermite). Edges that do not rise (e1 <= e0, possible only when every t_w so far is 0)
  // give 0: with no latency there is nothing to bias against.
  static double smoothstep(double e0, double e1, double v);
  // Eq. 7's b = β · smoothstep(0.96 t_bl, 1.2 t_bu, t_b).
  static double mip_bias(double beta, double t_bl, double t_bu, double t_b);

 private:
  explicit AdaptiveController(const ControllerParams& params);

  ControllerParams params_;
  State state_;
  HeadroomController headroom_;
  uint64_t accepted_ = 0;
  uint64_t rejected_ = 0;
};

}  // namespace texstream::stream
