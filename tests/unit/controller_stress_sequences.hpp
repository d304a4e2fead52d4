#pragma once
// Adversarial and random frame-latency sequences for the adaptive controller (issue 7), shared by the unit
// test (controller_stress_test.cpp, a reduced count) and `texstream-bench controller` (the full 10^6 and the
// 10^8-step drift run). Header-only, deterministic (splitmix64, no <random> distributions whose output
// depends on the standard library), no clock.
//
// run_stress: every sequence starts from a copy of a prepared controller (fresh, or warmed up so that l, the
// windows and the edges are not trivial), with one of several parameter sets (Table 2, extreme α and β,
// s_min = s_max), and feeds it one family of inputs. After every step it checks what the controller promises:
// the input is accepted exactly when it is finite, >= 0 and <= kMaxFrameLatencyS; a rejected input changes
// no state; s ∈ [s_min, s_max], b ∈ [0, β], l ∈ [0, 1], and every latency in the state is finite and >= 0.
//
// run_drift: a long run whose t_wa and t_b window means are compared, at checkpoints, with a recomputation
// from the controller's own t_w outputs (long double sum of the last 200 / 5); a plain double running sum
// is kept alongside to show the drift the exact sums avoid.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "texstream/stream/adaptive_controller.hpp"

namespace texstream::controller_stress {

// splitmix64 (Steele, Lea, Flood 2014): small, fast, and the same numbers everywhere.
class Rng {
 public:
  explicit Rng(uint64_t seed) : s_(seed) {}
  uint64_t next() {
    uint64_t z = (s_ += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }  // [0, 1)
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  double log_uniform(double lo, double hi) { return lo * std::pow(hi / lo, uniform()); }
  bool chance(double p) { return uniform() < p; }

 private:
  uint64_t s_;
};

enum class Family : uint32_t {
  kRandomUniform,  // 0..100 ms
  kLogUniform,     // 1 ns .. 10 s
  kZeros,
  kDenormals,            // subnormal doubles
  kMicrosecond,          // 1 µs frames (l climbs as fast as Eq. 4 lets it)
  kTenSecondSpikes,      // 16 ms frames with 10 s spikes
  kAlternatingExtremes,  // 0 / 10 s / 1 µs / 3600 s (the largest accepted) alternating
  kSlowDrift,            // 1 ms drifting to 1 s and back
  kNaN,                  // quiet and signalling NaNs among normal frames
  kInfinities,           // ±inf among normal frames
  kNegative,             // negative values (and -0.0) among normal frames
  kAbsurd,               // just above the accepted maximum, 1e300, DBL_MAX
  kRandomBits,           // any 64-bit pattern reinterpreted as a double
  kBadBytes,             // normal latencies, uploaded bytes or mip counts NaN, ±inf, negative or absurd
  kCount
};
const char* family_name(Family f);

struct StressOptions {
  uint64_t sequences = 1000000;
  size_t steps_per_sequence = 48;
  uint64_t seed = 7;
};

struct StressResult {
  uint64_t sequences = 0;
  uint64_t steps = 0;
  uint64_t inputs_rejected = 0;
  uint64_t bad_outputs = 0;   // steps where any promise above was broken
  std::string first_failure;  // what broke first (empty when none)
  uint64_t per_family[static_cast<uint32_t>(Family::kCount)] = {};
};

struct DriftResult {
  uint64_t steps = 0;
  uint64_t checkpoints = 0;
  double max_twa_error_s = 0;  // |controller t_wa window mean - recomputation|, worst checkpoint
  double max_tb_error_s = 0;
  double max_naive_twa_error_s = 0;  // the same for a plain double running sum
};

// ---- implementation ----

inline const char* family_name(Family f) {
  static const char* names[] = {"random_uniform", "log_uniform", "zeros",       "denormals", "microsecond",
                                "10s_spikes",     "alternating", "slow_drift",  "nan",       "infinities",
                                "negative",       "absurd",      "random_bits", "bad_bytes"};
  const auto i = static_cast<uint32_t>(f);
  return i < static_cast<uint32_t>(Family::kCount) ? names[i] : "?";
}

inline double from_bits(uint64_t bits) {
  double d;
  std::memcpy(&d, &bits, sizeof d);
  return d;
}

// Step `i` of a sequence of family `f`.
inline double sample(Family f, Rng& rng, size_t i, size_t n) {
  constexpr double kMax = stream::AdaptiveController::kMaxFrameLatencyS;
  const double normal = rng.uniform(0.002, 0.05);
  switch (f) {
    case Family::kRandomUniform:
      return rng.uniform(0.0, 0.1);
    case Family::kLogUniform:
      return rng.log_uniform(1e-9, 10.0);
    case Family::kZeros:
      return rng.chance(0.9) ? 0.0 : normal;
    case Family::kDenormals:
      return from_bits(1 + (rng.next() & ((1ull << 52) - 1)));  // positive subnormals
    case Family::kMicrosecond:
      return 1e-6;
    case Family::kTenSecondSpikes:
      return rng.chance(0.1) ? 10.0 : 0.016;
    case Family::kAlternatingExtremes: {
      static constexpr double kPattern[] = {0.0, 10.0, 1e-6, kMax, 4.9e-324, kMax, 0.0};
      return kPattern[(i + rng.next() % 2) % (sizeof kPattern / sizeof kPattern[0])];
    }
    case Family::kSlowDrift: {
      const double phase = static_cast<double>(i) / static_cast<double>(n > 1 ? n - 1 : 1);
      const double up = phase < 0.5 ? 2 * phase : 2 - 2 * phase;
      return 0.001 * std::pow(1000.0, up);
    }
    case Family::kNaN:
      if (!rng.chance(0.3)) return normal;
      return rng.chance(0.5) ? std::numeric_limits<double>::quiet_NaN()
                             : (rng.chance(0.5) ? std::numeric_limits<double>::signaling_NaN() : -std::nan(""));
    case Family::kInfinities:
      if (!rng.chance(0.3)) return normal;
      return rng.chance(0.5) ? std::numeric_limits<double>::infinity() : -std::numeric_limits<double>::infinity();
    case Family::kNegative: {
      if (!rng.chance(0.3)) return normal;
      static constexpr double kNeg[] = {-0.0, -1e-300, -4.9e-324, -0.016, -10.0, -1e308};
      return kNeg[rng.next() % (sizeof kNeg / sizeof kNeg[0])];
    }
    case Family::kAbsurd: {
      if (!rng.chance(0.3)) return normal;
      static const double kBig[] = {std::nextafter(kMax, 1e300), kMax * 2, 1e300, std::numeric_limits<double>::max()};
      return kBig[rng.next() % (sizeof kBig / sizeof kBig[0])];
    }
    case Family::kRandomBits:
      return from_bits(rng.next());
    case Family::kBadBytes:
      return normal;
    case Family::kCount:
      break;
  }
  return 0.0;
}

// The bytes uploaded in step `i` (mode auto fits its plant from them): mostly a plausible upload, sometimes
// none or an extreme; family kBadBytes feeds invalid ones, kRandomBits any bit pattern.
inline double sample_bytes(Family f, Rng& rng) {
  constexpr double kMaxBytes = stream::AdaptiveController::kMaxFrameBytes;
  if (f == Family::kRandomBits) return from_bits(rng.next());
  if (f == Family::kBadBytes && rng.chance(0.3)) {
    static const double kBad[] = {std::numeric_limits<double>::quiet_NaN(),
                                  std::numeric_limits<double>::infinity(),
                                  -std::numeric_limits<double>::infinity(),
                                  -1.0,
                                  -0.5,
                                  std::nextafter(kMaxBytes, 1e300),
                                  1e300};
    return kBad[rng.next() % (sizeof kBad / sizeof kBad[0])];
  }
  if (rng.chance(0.3)) return 0.0;
  if (rng.chance(0.05)) return rng.chance(0.5) ? kMaxBytes : 4.9e-324;
  return rng.log_uniform(1.0, 1e9);
}

// The mips uploaded in step `i` (mode auto fits their cost and paces by it): none, a few, a cut's burst, an
// extreme; family kBadBytes also feeds invalid counts, kRandomBits any bit pattern.
inline double sample_mips(Family f, Rng& rng) {
  constexpr double kMaxMips = stream::AdaptiveController::kMaxFrameMips;
  if (f == Family::kRandomBits) return from_bits(rng.next());
  if (f == Family::kBadBytes && rng.chance(0.2)) {
    static const double kBad[] = {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
                                  -1.0, std::nextafter(kMaxMips, 1e300), 1e300};
    return kBad[rng.next() % (sizeof kBad / sizeof kBad[0])];
  }
  if (rng.chance(0.3)) return 0.0;
  if (rng.chance(0.05)) return rng.chance(0.5) ? kMaxMips : 4.9e-324;
  return std::floor(rng.log_uniform(1.0, 4096.0));
}

// Parameter set `which` (0..9): five sets, each in mode seed (which < 5) and mode auto.
inline stream::ControllerParams stress_params(uint32_t which) {
  stream::ControllerParams p;  // Table 2
  p.mode = which < 5 ? ControllerMode::kSeed : ControllerMode::kAuto;
  switch (which % 5) {
    case 0:
      break;
    case 1:
      p.alpha_s = 1e-4;
      p.beta = 16;
      p.target_min_s = 0;
      p.pace_share = 100;
      break;  // tiny target, largest β and pace share config allows
    case 2:
      p.alpha_s = 10.0;
      p.beta = 0;
      p.target_min_s = 3600;
      break;  // huge target, no bias
    case 3:
      p.s_min_bytes = p.s_max_bytes = 0.065e6;
      break;  // s pinned
    case 4:
      p.alpha_s = 0.030;
      p.beta = 4;
      p.s_min_bytes = 1;
      p.s_max_bytes = 1e5 * 1e6;
      p.target_cap_s = 1e-6;
      p.pace_share = 0;
      break;  // config extremes, no pacing
  }
  return p;
}

// A controller in a non-trivial state: fresh (warm = 0), after steady fast frames (l > 0), or after noisy ones.
inline stream::AdaptiveController warmed(const stream::ControllerParams& p, uint32_t warm, uint64_t seed) {
  auto c = stream::AdaptiveController::create(p);
  stream::AdaptiveController ctl = std::move(*c);
  Rng rng(seed);
  for (int i = 0; i < 300 && warm != 0; ++i)
    ctl.on_frame(warm == 1 ? 0.004 : rng.uniform(0.003, 0.06), warm == 1 ? 0.0 : rng.uniform(0.0, 64e6),
                 warm == 1 ? 0.0 : std::floor(rng.uniform(0.0, 600.0)));
  return ctl;
}

inline bool accepted_input(double dt, double bytes = 0.0, double mips = 0.0) {
  return std::isfinite(dt) && dt >= 0.0 && dt <= stream::AdaptiveController::kMaxFrameLatencyS &&
         std::isfinite(bytes) && bytes >= 0.0 && bytes <= stream::AdaptiveController::kMaxFrameBytes &&
         std::isfinite(mips) && mips >= 0.0 && mips <= stream::AdaptiveController::kMaxFrameMips;
}

// Empty when every promise holds after a step.
inline std::string check_outputs(const stream::AdaptiveController& c) {
  const auto& p = c.params();
  const auto& s = c.state();
  const double sz = c.load_size_bytes(), b = c.mip_bias();
  if (!std::isfinite(sz)) return "load size not finite";
  // Every mode keeps the ranges (ControllerParams::validate holds the fixed mode's values to them).
  if (sz < p.s_min_bytes || sz > p.s_max_bytes) return "load size outside [s_min, s_max]";
  if (!(std::isfinite(b) && b >= 0.0 && b <= p.beta)) return "mip bias outside [0, beta]";
  if (!(s.l >= 0.0 && s.l <= 1.0)) return "load factor outside [0, 1]";
  const double lat[] = {s.t_w, s.t_wa, s.t_m, s.t_b, s.t_bl, s.t_bu};
  for (double v : lat) {
    if (!(std::isfinite(v) && v >= 0.0)) return "a latency in the state is not finite and >= 0";
  }
  if (!std::isfinite(s.x)) return "x not finite";
  if (s.t_bl > s.t_bu) return "t_bl above t_bu";
  const auto& h = c.headroom().state();
  if (!(std::isfinite(h.f_s) && h.f_s >= 0.0)) return "auto: latency without streaming not finite and >= 0";
  if (!(std::isfinite(h.k_s_per_mb) && h.k_s_per_mb >= 0.0)) return "auto: upload cost not finite and >= 0";
  if (!(std::isfinite(h.target_s) && h.target_s > 0.0)) return "auto: target not finite and > 0";
  if (!(std::isfinite(h.c_s_per_mip) && h.c_s_per_mip >= 0.0)) return "auto: mip cost not finite and >= 0";
  using H = stream::HeadroomController;
  const double pace = c.pace_mips();
  if (!(pace >= H::kPaceMinMips && pace <= H::kNoPace)) return "pace outside [kPaceMinMips, kNoPace]";
  if (p.mode != ControllerMode::kAuto && pace != H::kNoPace) return "a pace outside mode auto";
  if (p.mode == ControllerMode::kAuto && p.pace_share == 0 && pace != H::kNoPace) return "a pace with pacing off";
  return {};
}

inline StressResult run_stress(const StressOptions& o) {
  StressResult r;
  constexpr uint32_t kFamilies = static_cast<uint32_t>(Family::kCount);
  // Prepared starting points: 5 parameter sets × 3 warm-ups, copied for each sequence.
  std::vector<stream::AdaptiveController> bases;
  for (uint32_t ps = 0; ps < 10; ++ps) {
    for (uint32_t w = 0; w < 3; ++w) bases.push_back(warmed(stress_params(ps), w, o.seed + ps * 3 + w));
  }
  Rng rng(o.seed);
  for (uint64_t q = 0; q < o.sequences; ++q) {
    const auto fam = static_cast<Family>(q % kFamilies);
    stream::AdaptiveController c = bases[(q / kFamilies) % bases.size()];
    ++r.sequences;
    ++r.per_family[static_cast<uint32_t>(fam)];
    for (size_t i = 0; i < o.steps_per_sequence; ++i) {
      const double dt = sample(fam, rng, i, o.steps_per_sequence);
      const double bytes = sample_bytes(fam, rng);
      const double mips = sample_mips(fam, rng);
      const bool should = accepted_input(dt, bytes, mips);
      std::string what;
      if (should) {
        if (!c.on_frame(dt, bytes, mips)) what = "a valid input was rejected";
      } else {
        const stream::AdaptiveController::State before = c.state();
        const stream::HeadroomController::State before_auto = c.headroom().state();
        const uint64_t rejected = c.frames_rejected();
        if (c.on_frame(dt, bytes, mips)) {
          what = "an invalid input was accepted";
        } else if (!(c.state() == before) || !(c.headroom().state() == before_auto)) {
          what = "a rejected input changed the state";
        } else if (c.frames_rejected() != rejected + 1) {
          what = "a rejected input was not counted";
        }
        ++r.inputs_rejected;
      }
      if (what.empty()) what = check_outputs(c);
      ++r.steps;
      if (!what.empty()) {
        ++r.bad_outputs;
        if (r.first_failure.empty()) {
          char buf[200];
          std::snprintf(buf, sizeof buf, "sequence %llu (%s, mode %s) step %zu, input %a s %a bytes %a mips: ",
                        static_cast<unsigned long long>(q), family_name(fam),
                        std::string(choice_name(c.params().mode)).c_str(), i, dt, bytes, mips);
          r.first_failure = buf + what;
        }
      }
    }
  }
  return r;
}

inline DriftResult run_drift(uint64_t steps, uint64_t seed, uint64_t checkpoint_every = 9973) {
  DriftResult r;
  auto created = stream::AdaptiveController::create(stream::ControllerParams{});
  stream::AdaptiveController c = std::move(*created);
  constexpr size_t kN = stream::AdaptiveController::kTwaSamples, kB = stream::AdaptiveController::kTbSamples;
  std::vector<double> ring(kN, 0.0);  // the last 200 t_w outputs, as doubles
  size_t filled = 0;
  double naive_sum = 0.0;  // add the new, subtract the one leaving: what drifts
  Rng rng(seed);
  auto check = [&] {
    const size_t n = std::min(filled, kN), nb = std::min(filled, kB);
    long double sum = 0, sum_b = 0;
    for (size_t k = 0; k < n; ++k) {
      const long double v = ring[(filled - 1 - k) % kN];
      sum += v;
      if (k < nb) sum_b += v;
    }
    const double exact = static_cast<double>(sum / static_cast<long double>(n));
    const double exact_b = static_cast<double>(sum_b / static_cast<long double>(nb));
    r.max_twa_error_s = std::max(r.max_twa_error_s, std::fabs(c.state().twa_window.mean_s() - exact));
    r.max_tb_error_s = std::max(r.max_tb_error_s, std::fabs(c.state().tb_window.mean_s() - exact_b));
    r.max_naive_twa_error_s = std::max(r.max_naive_twa_error_s, std::fabs(naive_sum / static_cast<double>(n) - exact));
    ++r.checkpoints;
  };
  for (uint64_t i = 0; i < steps; ++i) {
    // Mostly ordinary frames of 1 µs .. 100 ms, with rare 10 s spikes and runs of 1 µs frames: large values
    // entering and leaving a window of small ones is what makes a floating-point running sum drift.
    double dt;
    const double u = rng.uniform();
    if (u < 0.001) {
      dt = 10.0;
    } else if (u < 0.2) {
      dt = 1e-6;
    } else {
      dt = rng.log_uniform(1e-6, 0.1);
    }
    c.on_frame(dt);
    const double tw = c.state().t_w;
    if (filled >= kN) naive_sum -= ring[filled % kN];
    ring[filled % kN] = tw;
    naive_sum += tw;
    ++filled;
    if ((i + 1) % checkpoint_every == 0) check();
  }
  if (filled) check();
  r.steps = steps;
  return r;
}

}  // namespace texstream::controller_stress
