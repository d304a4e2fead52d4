#include "texstream/stream/adaptive_controller.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "texstream/common/contract.hpp"

namespace texstream::stream {

namespace {

// Eq. 6: how far t_m moves from t_wa toward α — 0.85 when the recent weighted latency is above the target
// (pin the threshold near α), 0.5 otherwise (let it follow a low t_wa so a quiet period does not invite a burst).
constexpr double kThresholdPullAbove = 0.85;
constexpr double kThresholdPullBelow = 0.5;
// Eq. 5's decay rate constant: t_w falls by (30 d)^2 Δt per frame (d, Δt in seconds).
constexpr double kDecayRate = 30.0;
// Eq. 7: the edges weight the current t_w by 1 - 0.8 and the windowed min/max by 0.8; the lower edge is
// lowered by 0.96 and the upper raised by 1.2 before the smoothstep.
constexpr double kEdgeHistoryWeight = 0.8;
constexpr double kLowerEdgeScale = 0.96;
constexpr double kUpperEdgeScale = 1.2;

// An hour: as AdaptiveController::kMaxFrameLatencyS.
constexpr double kMaxTargetS = 3600.0;
constexpr double kMaxPaceShare = 100.0;  // controller.pace_share: streaming may take up to 100 f a frame

bool finite_non_negative(double v) { return std::isfinite(v) && v >= 0.0; }

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

Error bad(const std::string& key, const std::string& why) {
  return make_error(ErrorCode::kInvalidArgument, "controller." + key + ": " + why);
}

}  // namespace

// ---- parameters ----

Result<ControllerParams> ControllerParams::from_config(const ControllerConfig& c) {
  ControllerParams p;
  p.mode = c.mode;
  p.alpha_s = c.alpha_ms / 1e3;  // Table 2 gives α in ms; the equations run in seconds
  p.beta = c.beta;
  p.s_min_bytes = c.s_min_mb * 1e6;  // MB = 10^6 bytes (Table 2's 0.065 MB is one 64 KiB block)
  p.s_max_bytes = c.s_max_mb * 1e6;
  p.fixed_load_bytes = c.fixed_load_mb * 1e6;
  p.fixed_bias = c.fixed_bias;
  p.target_min_s = c.target_min_ms / 1e3;
  p.target_cap_s = c.target_ms / 1e3;
  p.pace_share = c.pace_share;
  TS_TRY(p.validate());
  return p;
}

Status ControllerParams::validate() const {
  if (!(std::isfinite(alpha_s) && alpha_s > 0))
    return bad("alpha_ms", "must be a positive number, not " + num(alpha_s * 1e3));
  if (!finite_non_negative(beta)) return bad("beta", "must be a non-negative number, not " + num(beta));
  if (!(std::isfinite(s_min_bytes) && s_min_bytes >= 1)) {
    return bad("s_min_mb", "must be at least one byte, not " + num(s_min_bytes / 1e6) + " MB");
  }
  if (!(std::isfinite(s_max_bytes) && s_max_bytes < 1.8e19)) {
    return bad("s_max_mb", "must be a finite byte count, not " + num(s_max_bytes / 1e6) + " MB");
  }
  if (s_min_bytes > s_max_bytes) return bad("s_min_mb", "must not exceed controller.s_max_mb");
  if (!(std::isfinite(target_min_s) && target_min_s >= 0 && target_min_s <= kMaxTargetS)) {
    return bad("target_min_ms", "must be a number in [0, 3600000], not " + num(target_min_s * 1e3));
  }
  if (!(std::isfinite(target_cap_s) && target_cap_s >= 0 && target_cap_s <= kMaxTargetS)) {
    return bad("target_ms", "must be 0 (automatic) or a number up to 3600000, not " + num(target_cap_s * 1e3));
  }
  if (!(std::isfinite(pace_share) && pace_share >= 0 && pace_share <= kMaxPaceShare)) {
    return bad("pace_share", "must be 0 (no pacing) or a number up to 100, not " + num(pace_share));
  }
  if (mode == ControllerMode::kFixed) {
    // The fixed mode is held to the same output ranges as the others rather than silently clamped.
    if (!(fixed_load_bytes >= s_min_bytes && fixed_load_bytes <= s_max_bytes)) {
      return bad("fixed_load_mb", num(fixed_load_bytes / 1e6) +
                                      " MB is outside [controller.s_min_mb, controller.s_max_mb] = [" +
                                      num(s_min_bytes / 1e6) + ", " + num(s_max_bytes / 1e6) + "] MB");
    }
    if (!(fixed_bias >= 0 && fixed_bias <= beta)) {
      return bad("fixed_bias", num(fixed_bias) + " is outside [0, controller.beta] = [0, " + num(beta) + "]");
    }
  }
  return ok_status();
}

// ---- windows ----

template <size_t N>
void LatencyWindow<N>::push(double seconds) {
  TS_ASSERT(seconds >= 0 && seconds <= AdaptiveController::kMaxFrameLatencyS, "window sample %g s out of range",
            seconds);
  const auto fs = static_cast<int64_t>(std::llround(seconds * kFemtosPerSecond));
  if (count_ == N) {
    sum_fs_ -= values_[next_];
  } else {
    ++count_;
  }
  values_[next_] = fs;
  sum_fs_ += fs;
  next_ = (next_ + 1) % N;
}

template <size_t N>
double LatencyWindow<N>::mean_s() const {
  if (count_ == 0) return 0.0;
  // The sum is exact; this division is the only rounding, made afresh every time (nothing accumulates).
  return static_cast<double>(sum_fs_) / static_cast<double>(count_) / kFemtosPerSecond;
}

template class LatencyWindow<AdaptiveController::kTwaSamples>;
template class LatencyWindow<AdaptiveController::kTbSamples>;

// ---- the equations ----

double AdaptiveController::load_polynomial(double x) {
  const double a = std::fabs(x);
  const double p2 = 10.0 * a, p3 = 30.0 * a, p4 = 50.0 * a;
  return a + p2 * p2 + p3 * p3 * p3 + (p4 * p4) * (p4 * p4);
}

double AdaptiveController::load_factor_step(double x, double dt) {
  // sign(-x): l falls while t_w is above the threshold, rises while below, holds at x = 0.
  const double sign = x > 0 ? -1.0 : (x < 0 ? 1.0 : 0.0);
  return sign * load_polynomial(x) * dt;
}

double AdaptiveController::weighted_latency(double t_w_prev, double dt) {
  const double d = std::max(t_w_prev - dt, 0.0);
  const double decay = (kDecayRate * d) * (kDecayRate * d) * dt;
  return std::max(t_w_prev - decay, dt);
}

double AdaptiveController::threshold(double t_wa, double alpha) {
  const double w = t_wa > alpha ? kThresholdPullAbove : kThresholdPullBelow;
  return t_wa * (1.0 - w) + alpha * w;
}

double AdaptiveController::smoothstep(double e0, double e1, double v) {
  if (!(e1 > e0)) return 0.0;
  double t = (v - e0) / (e1 - e0);
  // `!(t > 0)` also catches a NaN from 0/0-like underflow of denormal edges.
  if (!(t > 0.0)) t = 0.0;
  if (t > 1.0) t = 1.0;
  return std::min(t * t * (3.0 - 2.0 * t), 1.0);  // rounding must not lift b above β
}

double AdaptiveController::mip_bias(double beta, double t_bl, double t_bu, double t_b) {
  return beta * smoothstep(kLowerEdgeScale * t_bl, kUpperEdgeScale * t_bu, t_b);
}

// ---- the controller ----

HeadroomParams headroom_params(const ControllerParams& p) {
  HeadroomParams h;
  h.s_min_bytes = p.s_min_bytes;
  h.s_max_bytes = p.s_max_bytes;
  h.beta = p.beta;
  h.target_min_s = p.target_min_s;
  h.target_cap_s = p.target_cap_s;
  h.pace_share = p.pace_share;
  return h;
}

AdaptiveController::AdaptiveController(const ControllerParams& params)
    : params_(params), headroom_(headroom_params(params)) {}

Result<AdaptiveController> AdaptiveController::create(const ControllerParams& params) {
  TS_TRY(params.validate());
  AdaptiveController c(params);
  c.state_.s_bytes = params.s_min_bytes;  // l = 0 (Eq. 4: s = max(0 · s_max, s_min))
  return c;
}

bool AdaptiveController::on_frame(double dt, double bytes, double mips) {
  if (!(std::isfinite(dt) && dt >= 0.0 && dt <= kMaxFrameLatencyS && std::isfinite(bytes) && bytes >= 0.0 &&
        bytes <= kMaxFrameBytes && std::isfinite(mips) && mips >= 0.0 && mips <= kMaxFrameMips)) {
    ++rejected_;
    return false;
  }
  ++accepted_;
  State& s = state_;

  // Eq. 5. t_w >= Δt and t_w <= max(t_w_prev, Δt): it stays in [0, kMaxFrameLatencyS].
  s.t_w = weighted_latency(s.t_w, dt);

  // Eq. 6 over the previous 200 t_w (fewer while the run is younger; the current t_w before the first).
  s.t_wa = s.twa_window.count() ? s.twa_window.mean_s() : s.t_w;
  s.t_m = threshold(s.t_wa, params_.alpha_s);

  // Eq. 4. P · Δt is at most (50 · 3600)^4 · 3600 ≈ 4·10^24: finite, and the clamp brings l back to [0, 1].
  s.x = s.t_w - s.t_m;
  s.l = std::clamp(s.l + load_factor_step(s.x, dt), 0.0, 1.0);
  s.s_bytes = std::max(s.l * params_.s_max_bytes, params_.s_min_bytes);

  // Eq. 7. t_b: previous 5 t_w. Edges: 0.2 · t_w + 0.8 · mean over the previous 40 edges of min/max(edge, t_w)
  // — the min/max with the current t_w is why these are recomputed from the window rather than summed.
  s.t_b = s.tb_window.count() ? s.tb_window.mean_s() : s.t_w;
  if (s.bl_history.count == 0) {
    s.t_bl = s.t_w;
    s.t_bu = s.t_w;
  } else {
    double lo = 0.0, hi = 0.0;
    for (size_t j = 0; j < s.bl_history.count; ++j) {
      lo += std::min(s.bl_history.values[j], s.t_w);
      hi += std::max(s.bu_history.values[j], s.t_w);
    }
    const auto n = static_cast<double>(s.bl_history.count);
    s.t_bl = s.t_w * (1.0 - kEdgeHistoryWeight) + (lo / n) * kEdgeHistoryWeight;
    s.t_bu = s.t_w * (1.0 - kEdgeHistoryWeight) + (hi / n) * kEdgeHistoryWeight;
  }
  s.b = mip_bias(params_.beta, s.t_bl, s.t_bu, s.t_b);

  s.twa_window.push(s.t_w);
  s.tb_window.push(s.t_w);
  s.bl_history.push(s.t_bl);
  s.bu_history.push(s.t_bu);

  // The ranges hold by construction for any accepted Δt; a violation is a bug in the lines above.
  TS_ASSERT(std::isfinite(s.s_bytes) && s.s_bytes >= params_.s_min_bytes && s.s_bytes <= params_.s_max_bytes,
            "load size %g outside [%g, %g]", s.s_bytes, params_.s_min_bytes, params_.s_max_bytes);
  TS_ASSERT(s.b >= 0.0 && s.b <= params_.beta, "mip bias %g outside [0, %g]", s.b, params_.beta);
  TS_ASSERT(s.l >= 0.0 && s.l <= 1.0, "load factor %g outside [0, 1]", s.l);
  if (params_.mode == ControllerMode::kAuto) headroom_.on_frame(dt, bytes, mips);
  return true;
}

double AdaptiveController::load_size_bytes() const {
  switch (params_.mode) {
    case ControllerMode::kAuto:
      return headroom_.load_size_bytes();
    case ControllerMode::kSeed:
      return state_.s_bytes;
    case ControllerMode::kNone:
      return params_.s_max_bytes;
    case ControllerMode::kFixed:
      return params_.fixed_load_bytes;
  }
  return params_.s_min_bytes;
}

uint64_t AdaptiveController::load_bytes() const { return static_cast<uint64_t>(load_size_bytes()); }

double AdaptiveController::mip_bias() const {
  switch (params_.mode) {
    case ControllerMode::kAuto:
      return headroom_.mip_bias();
    case ControllerMode::kSeed:
      return state_.b;
    case ControllerMode::kNone:
      return 0.0;
    case ControllerMode::kFixed:
      return params_.fixed_bias;
  }
  return 0.0;
}

double AdaptiveController::pace_mips() const {
  return params_.mode == ControllerMode::kAuto ? headroom_.pace_mips() : HeadroomController::kNoPace;
}

double AdaptiveController::target_s() const {
  switch (params_.mode) {
    case ControllerMode::kAuto:
      return headroom_.target_s();
    case ControllerMode::kSeed:
      return params_.alpha_s;
    case ControllerMode::kNone:
    case ControllerMode::kFixed:
      break;
  }
  return 0.0;
}

}  // namespace texstream::stream
