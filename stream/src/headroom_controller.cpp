#include "texstream/stream/headroom_controller.hpp"

#include <algorithm>
#include <array>
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

namespace {

// Non-negative least squares of y on one or two regressors, from centred sums (S_ij = Σ (x_i − x̄_i)(x_j − x̄_j),
// S_iy likewise): every support (both, the first, the second) is tried and the feasible one that explains most
// of y is kept. Coefficients stay 0 unless the fit explains y with a multiple correlation of at least `min_r`.
// `use` says which regressors take part; the others get 0.
std::array<double, 2> nonnegative_fit(const std::array<std::array<double, 2>, 2>& sxx, const std::array<double, 2>& sxy,
                                      double syy, std::array<bool, 2> use, double min_r) {
  std::array<double, 2> best{0, 0};
  double best_explained = 0;
  auto consider = [&](std::array<double, 2> b) {
    if (!(b[0] >= 0 && b[1] >= 0 && std::isfinite(b[0]) && std::isfinite(b[1]))) return;
    const double explained = b[0] * sxy[0] + b[1] * sxy[1];
    if (explained > best_explained) {
      best_explained = explained;
      best = b;
    }
  };
  for (int i = 0; i < 2; ++i) {
    if (use[i] && sxx[i][i] > 0) {
      std::array<double, 2> b{0, 0};
      b[i] = sxy[i] / sxx[i][i];
      consider(b);
    }
  }
  const double det = sxx[0][0] * sxx[1][1] - sxx[0][1] * sxx[0][1];
  // Both only when they are not (nearly) collinear: a 1e-6 relative determinant is a correlation above 0.999999.
  if (use[0] && use[1] && det > 1e-6 * sxx[0][0] * sxx[1][1]) {
    consider({(sxx[1][1] * sxy[0] - sxx[0][1] * sxy[1]) / det, (sxx[0][0] * sxy[1] - sxx[0][1] * sxy[0]) / det});
  }
  if (!(syy > 0) || best_explained < min_r * min_r * syy) return {0, 0};
  return best;
}

}  // namespace

void HeadroomController::fit() {
  State& s = state_;
  const size_t n = s.count;
  const double nn = static_cast<double>(n);
  double min_dt = std::numeric_limits<double>::infinity();
  double mean_dt = 0, mean_mb = 0, mean_mips = 0;
  double max_mb = 0, min_mb = std::numeric_limits<double>::infinity();
  double max_mips = 0, min_mips = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < n; ++i) {
    min_dt = std::min(min_dt, s.dt[i]);
    max_mb = std::max(max_mb, s.mb[i]);
    min_mb = std::min(min_mb, s.mb[i]);
    max_mips = std::max(max_mips, s.mips[i]);
    min_mips = std::min(min_mips, s.mips[i]);
    mean_dt += s.dt[i] / nn;
    mean_mb += s.mb[i] / nn;
    mean_mips += s.mips[i] / nn;
  }
  // k and c are plant knowledge: a regressor whose window does not vary enough (a pause: no uploads, or
  // none of a burst's mip counts) keeps its last estimate, and its part is taken out of the latencies before
  // the other is refitted. A refit finds 0 for a regressor that does not explain the latencies.
  double k = s.k_s_per_mb, c = s.c_s_per_mip;
  const bool fit_k = n >= kMinFitFrames && max_mb - min_mb >= kMinSpreadMb;
  const bool fit_c = n >= kMinFitFrames && max_mips - min_mips >= kPaceSpreadMips;
  if (fit_k || fit_c) {
    // Least squares over the window, recomputed every frame (nothing accumulates), non-negative: uploading
    // cannot make a frame faster, so a negative slope is noise or a view change. Bytes and mips come together
    // in a burst; fitting them jointly keeps a GPU's per-mip cost (binds, copy regions) from passing for a
    // per-byte one (docs/controller.md, "pace").
    std::array<std::array<double, 2>, 2> sxx{};
    std::array<double, 2> sxy{};
    double syy = 0;
    for (size_t i = 0; i < n; ++i) {
      const double x0 = s.mb[i] - mean_mb, x1 = s.mips[i] - mean_mips;
      double y = s.dt[i] - mean_dt;
      if (!fit_k) y -= k * x0;
      if (!fit_c) y -= c * x1;
      sxx[0][0] += x0 * x0;
      sxx[0][1] += x0 * x1;
      sxx[1][1] += x1 * x1;
      sxy[0] += x0 * y;
      sxy[1] += x1 * y;
      syy += y * y;
    }
    const std::array<double, 2> b = nonnegative_fit(sxx, sxy, syy, {fit_k, fit_c}, kMinCorrelation);
    if (fit_k) k = b[0];
    if (fit_c) c = b[1];
  }
  double f = min_dt;
  if (k > 0 || c > 0) {
    for (size_t i = 0; i < n; ++i) f = std::min(f, s.dt[i] - k * s.mb[i] - c * s.mips[i]);
  }
  s.k_s_per_mb = k;
  s.c_s_per_mip = c;
  s.f_s = std::clamp(f, kFloorShare * min_dt, min_dt);  // NaN cannot reach here: inputs are finite
}

void HeadroomController::fit_pace() {
  State& s = state_;
  // A frame's streaming work stays within share · f, and under the growth line: B / c mips (no cap while c
  // is unknown or pacing is off).
  s.pace_mips = kNoPace;
  if (params_.pace_share > 0 && s.c_s_per_mip > 0) {
    const double line = s.f_s + kGrowBelow * (s.target_s - s.f_s);
    const double budget = std::min(params_.pace_share * s.f_s, line - s.f_s);
    s.pace_mips = std::clamp(budget / s.c_s_per_mip, kPaceMinMips, kNoPace);
  }
}

void HeadroomController::on_frame(double dt_s, double bytes, double mips) {
  TS_ASSERT(std::isfinite(dt_s) && dt_s >= 0 && std::isfinite(bytes) && bytes >= 0 && std::isfinite(mips) && mips >= 0,
            "headroom controller input out of contract: dt %g bytes %g mips %g", dt_s, bytes, mips);
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
  s.mips[s.next] = mips;
  s.next = (s.next + 1) % kWindow;
  s.count = std::min(s.count + 1, kWindow);
  fit();
  s.target_s = target(s.f_s, params_);
  fit_pace();
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
  TS_ASSERT(std::isfinite(s.s_bytes) && s.b >= 0 && s.b <= params_.beta &&
                (s.pace_mips >= kPaceMinMips && s.pace_mips <= kNoPace),
            "headroom output out of range: s %g b %g pace %g", s.s_bytes, s.b, s.pace_mips);
}

}  // namespace texstream::stream
