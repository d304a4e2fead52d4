#include "texstream/stream/headroom_controller.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "texstream/common/contract.hpp"
#include "texstream/stream/adaptive_controller.hpp"

namespace texstream::stream {

HeadroomController::HeadroomController(const HeadroomParams& p) : params_(p) {
  // Start at s_max: nothing says yet that streaming costs frame time, and the first cycles ask mostly for 4x4
  // mips (a few bytes each). Starting at s_min cost 5 frames of ramp on an H200 (300 K city: ∫MSE 6 % above
  // the baseline's in the first second); a first stutter is cut in the frame it happens.
  state_.s_bytes = p.s_max_bytes;
  state_.target_s = std::max(p.target_min_s, kMinTargetS);
}

double HeadroomController::target(double f_s, const HeadroomParams& p) {
  double t = std::max(kTargetFactor * f_s, p.target_min_s);
  if (p.target_cap_s > 0) t = std::min(t, std::max(p.target_cap_s, kCapHeadroom * f_s));
  return std::max(t, kMinTargetS);
}

double HeadroomController::load_factor(double t_w_s, double dt_s, double f_s, double target_s) {
  if (dt_s > target_s) {
    // This frame is over the target: a stutter (twice the target or more) drops s to s_min at once, as Eq. 4's
    // quartic does for a spike of tens of ms; a smaller overshoot cuts by (T / Δt)^4, e.g. 0.68 at 10 % over.
    // By Δt, not t_w: Eq. 5 keeps a spike for tens of frames, and cutting again on every one of them would
    // compound one stutter into s_min; nor may a target that fell with a cheaper view (a cut) cut s.
    if (dt_s >= kStutterRatio * target_s) return 0.0;
    const double r = target_s / dt_s;
    return (r * r) * (r * r);
  }
  // Growth by the room this frame's latency leaves below the line: ×4 at f, ×1 at the line. While t_w
  // (Eq. 5) still remembers a spike above the line, growth is gentle (×2^(room/2)): the spike may come back.
  const double line = f_s + kGrowBelow * (target_s - f_s);
  if (dt_s >= line) return 1.0;
  const double room = line > f_s ? std::clamp((line - dt_s) / (line - f_s), 0.0, 1.0) : 1.0;
  return std::exp2((t_w_s <= line ? kGrowthDoublings : 0.5) * room);
}

double HeadroomController::bias(double beta, double t_b_s, double target_s) {
  // The seed's smoothstep (Eq. 7's), over t_b / T from kBiasFrom to kBiasFull.
  return beta * AdaptiveController::smoothstep(kBiasFrom, kBiasFull, t_b_s / target_s);
}

void HeadroomController::fit() {
  State& s = state_;
  const size_t n = s.count;
  double min_dt = std::numeric_limits<double>::infinity();
  double sx = 0, sy = 0, sxx = 0, sxy = 0, syy = 0;
  double max_mb = 0, min_mb = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < n; ++i) {
    min_dt = std::min(min_dt, s.dt[i]);
    max_mb = std::max(max_mb, s.mb[i]);
    min_mb = std::min(min_mb, s.mb[i]);
    sx += s.mb[i];
    sy += s.dt[i];
    sxx += s.mb[i] * s.mb[i];
    sxy += s.mb[i] * s.dt[i];
    syy += s.dt[i] * s.dt[i];
  }
  // k is plant knowledge: a window without enough spread in its uploads (a pause) keeps the last estimate.
  // A window with spread refits it (and finds 0 when the uploads do not explain the latencies).
  double k = s.k_s_per_mb;
  if (n >= kMinFitFrames && max_mb - min_mb >= kMinSpreadMb) {
    k = 0;
    // Least squares over the window, recomputed every frame (nothing accumulates). Uploading cannot make a
    // frame faster: a negative slope is noise or a view change and counts as 0; a degenerate one as 0 too.
    const double nn = static_cast<double>(n);
    const double var = nn * sxx - sx * sx, cov = nn * sxy - sx * sy, var_y = nn * syy - sy * sy;
    // Only a slope that explains the latencies counts (correlation >= kMinCorrelation): on a GPU an upload
    // costs ~nothing and any slope is noise, or a heavier view that happened to bring more mips.
    const double r = var > 0 && var_y > 0 ? cov / std::sqrt(var * var_y) : 0.0;
    if (var > 0 && std::isfinite(cov / var) && r >= kMinCorrelation) k = std::max(cov / var, 0.0);
  }
  double f = min_dt;
  if (k > 0) {
    for (size_t i = 0; i < n; ++i) f = std::min(f, s.dt[i] - k * s.mb[i]);
  }
  s.k_s_per_mb = k;
  s.f_s = std::clamp(f, kFloorShare * min_dt, min_dt);  // NaN cannot reach here: inputs are finite
}

void HeadroomController::on_frame(double dt_s, double bytes) {
  TS_ASSERT(std::isfinite(dt_s) && dt_s >= 0 && std::isfinite(bytes) && bytes >= 0,
            "headroom controller input out of contract: dt %g bytes %g", dt_s, bytes);
  State& s = state_;
  // The first frame is start-up (pipelines, the first geometry): 40-420 ms on lavapipe, 200 ms on an H200
  // with a 300 K city. It says nothing about streaming, so it neither enters the fit nor cuts nor biases.
  if (!s.started) {
    s.started = true;
    return;
  }
  // Eq. 5's weighted maximum, from the first streaming frame on (the seed's own t_w carries the start-up
  // frame's latency for ten frames or more, and would cut s while the frames themselves have room).
  const double t_w_s = AdaptiveController::weighted_latency(s.t_w_s, dt_s);
  s.t_w_s = t_w_s;
  s.dt[s.next] = dt_s;
  s.mb[s.next] = bytes / kBytesPerUnit;
  s.next = (s.next + 1) % kWindow;
  s.count = std::min(s.count + 1, kWindow);
  fit();
  s.target_s = target(s.f_s, params_);
  // s never exceeds what the plant model says fits between f and the growth line in one frame: where uploads
  // cost frame time (lavapipe) a pause does not bank a full-size burst for the next cut; where they cost
  // nothing measurable (k = 0, a GPU) the cap is s_max.
  s.budget_bytes = params_.s_max_bytes;
  if (s.k_s_per_mb > 0) {
    const double line = s.f_s + kGrowBelow * (s.target_s - s.f_s);
    s.budget_bytes = std::min((line - s.f_s) / s.k_s_per_mb * kBytesPerUnit, params_.s_max_bytes);
  }
  const double cap = std::max(s.budget_bytes, params_.s_min_bytes);
  s.s_bytes = std::clamp(s.s_bytes * load_factor(t_w_s, dt_s, s.f_s, s.target_s), params_.s_min_bytes, cap);
  // Sustained overload: the mean of the last kBiasFrames latencies (not Eq. 7's t_b, whose t_w carries the
  // start-up frame for five frames).
  double sum = 0;
  const size_t n = std::min(s.count, kBiasFrames);
  for (size_t i = 0; i < n; ++i) sum += s.dt[(s.next + kWindow - 1 - i) % kWindow];
  s.t_b_s = sum / static_cast<double>(n);
  s.b = bias(params_.beta, s.t_b_s, s.target_s);
  TS_ASSERT(std::isfinite(s.s_bytes) && s.b >= 0 && s.b <= params_.beta, "headroom output out of range: s %g b %g",
            s.s_bytes, s.b);
}

}  // namespace texstream::stream
