// texstream-bench controller: the adaptive streaming controller (seed 000 §3.4, Eq. 4-7) proven before it
// drives the renderer (issue 7).
//   (a) stability: 10^6 random and adversarial latency sequences (tests/unit/controller_stress_sequences.hpp),
//       and without --quick the 10^8-step drift run of the windowed averages;
//   (b) a closed loop against a simulated plant (below) for α ∈ {12, 14, 16, 18} ms and the no-adaptive
//       baseline (s = s_max, b = 0) on the same plant and seed.
// Last line: summary: stress_sequences=N bad_outputs=B max_latency_reduction=R mbps_ratio=Q
// auto_max_latency_reduction=R2
//   auto_mbps_ratio=Q2 (R2, Q2: the same for controller.mode = auto)
//   R = 1 - max frame latency (α = 16 ms) / max frame latency (baseline); Q = MB/s (α = 16 ms) / MB/s (baseline).
//
// THE PLANT: a fly-through in the spirit of seed 000 §4.1 (68.6 s, the Berlin benchmark's length): the camera
// moves (visible textures are replaced at a steady rate), pauses four times for 2 s, and jumps to a new view
// four times (every visible texture replaced at once). Time is simulated: each frame advances it by the frame's
// own latency, so a stuttering run sees the same path in fewer frames. Each frame runs one streaming cycle of
// Algorithm 1 (one mip per texture, coarsest — 4x4 — first, refine while desired + b < resident, stop once the
// batch exceeds s or the cycle's loading time exceeds load_time) over the visible textures sorted by weight,
// and the frame pays for what the cycle loaded:
//   latency = base (+ slow scene-density swing) + noise + random system stutters
//           + upload · bytes + bind cost of the sparse pages bound,
// where the bind cost per page grows with the pages bound in the same frame and with the pages resident (the
// seed §2.3: "a linearly increasing memory block binding cost with every memory block bound"). Textures have
// the generator's extent histogram (2^2..2^9, median 2^7), BC1 (8 bytes per 4x4 block). Deterministic: the
// k-th texture to enter the view, its slot and every frame's noise derive from the seed by hashing, so all runs
// see the same textures in the same order. Constants are in PlantOptions with where each comes from.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "bench_registry.hpp"
#include "bench_util.hpp"
#include "controller_stress_sequences.hpp"
#include "texstream/stream/adaptive_controller.hpp"

namespace texstream::bench {
namespace {

using controller_stress::Rng;

struct PlantOptions {
  double duration_s = 68.6;              // seed 000 §4.1: the Berlin fly-through lasts 68.6 s
  size_t visible = 20000;                // textures in view at once (a bird's-eye view of a city)
  double replace_per_s = 2000;           // textures leaving/entering the view per second while the camera moves
  double pauses_s[4] = {6, 20, 35, 50};  // §4.1: "the camera will pause for 2 s" at four points
  double pause_length_s = 2.0;
  double switches_s[4] = {13, 28, 43, 58};  // §4.1: "immediately switch to a new view" at four points
  // Frame cost without streaming: Table 3's median frame latency is 4.5-6.8 ms on the seed's system.
  double base_ms = 5.0;
  double density_swing_ms = 1.0;     // dense vs sparse city areas: a slow ±1 ms swing (period 23 s)
  double noise_ms = 0.4;             // uniform ±0.4 ms frame-to-frame jitter
  double stutter_per_frame = 0.003;  // §4.2: stutters "randomly occurring ... cannot be fully eliminated"
  double stutter_min_ms = 2, stutter_max_ms = 10;
  // Streaming costs on the frame: upload ~1 GB/s effective (copy + layout), and sparse binds.
  double upload_ms_per_mb = 1.0;
  // Sparse binds (§2.3: "a linearly increasing memory block binding cost with every memory block bound, even
  // more so when memory blocks are bound sparsely and irregularly"). Per 64 KiB block:
  //   bind_ms_per_page · (1 + blocks this frame / bind_batch_pages) · (1 + blocks in the cache / bind_resident_pages).
  // The three constants are calibrated on the seed's BASELINE only (Table 3, no adaptive algorithms: median
  // 6.8 ms, max 471 ms, stutter "after about 5 s" as the cache fills); the adaptive runs are not tuned for.
  double bind_ms_per_page = 0.05;
  double bind_batch_pages = 50;
  double bind_resident_pages = 4096;  // per-page cost × (1 + pages in the cache / this)
  double cache_pages = 32768;         // the sparse cache: 2 GiB of 64 KiB blocks; full, blocks are recycled
  // Sparse block size (Table 2's s_min). Pages are counted as bytes / 64 KiB: textures share a layer's
  // blocks, and mips below a block live in the layer's mip tail, bound once.
  double page_bytes = 65536;
  // Loading inside the cycle (reads + staging): per-mip overhead plus bandwidth, cut at the load time.
  double load_us_per_mip = 8;
  double load_gb_per_s = 1.0;
  double tau_px2 = 150;  // Table 2 τ: meshes below this weight (≈ pixels) are not streamed
};

// BC1 bytes of mip `level` of a 2^e x 2^e texture: 8 bytes per 4x4 block, at least one block.
double mip_bytes(int e, int level) {
  const double side = std::max(1.0, std::ldexp(1.0, e - level) / 4.0);
  return side * side * 8.0;
}

uint64_t hash64(uint64_t a, uint64_t b) {
  Rng r(a * 0x9e3779b97f4a7c15ull ^ (b + 0x632be59bd9b4e019ull));
  r.next();
  return r.next();
}
double hash_unit(uint64_t a, uint64_t b) { return static_cast<double>(hash64(a, b) >> 11) * 0x1.0p-53; }

struct Texture {
  int e = 7;          // extent 2^e
  float desired = 0;  // mipLevelSampled (fractional)
  float weight = 0;   // ≈ fragment count
  int resident = -1;  // finest loaded level, -1: Initial
  bool final = false;
  uint32_t bucket = 0;  // priority bucket and position in it (see Plant)
  uint32_t pos = 0;
};

// The generator's extent histogram: 2^2..2^9 with median 2^7.
int draw_extent(double u) {
  static const double cum[] = {0.02, 0.05, 0.10, 0.20, 0.35, 0.65, 0.85, 1.0};  // e = 2..9
  for (int i = 0; i < 8; ++i) {
    if (u < cum[i]) return 2 + i;
  }
  return 9;
}

// Projected size 2..2048 px, log-uniform (a bird's-eye view spans near and far): the texture wants mip
// e - log2(size), clamped to its chain; its weight is its fragment count.
Texture make_texture(uint64_t seed, uint64_t k) {
  Texture t;
  t.e = draw_extent(hash_unit(seed, 4 * k));
  const double px = 2.0 * std::pow(1024.0, hash_unit(seed, 4 * k + 1));
  t.desired = static_cast<float>(std::clamp(t.e - std::log2(px), 0.0, static_cast<double>(std::max(0, t.e - 2))));
  t.weight = static_cast<float>(px * px);
  return t;
}

struct RunStats {
  std::string name;
  std::vector<double> latency_ms;
  double seconds = 0, bytes = 0, mips = 0;
  double sum_s_mb = 0, sum_b = 0, max_tw_ms = 0;
  uint64_t frames = 0;
};

// The visible set, in priority order. The paper sorts the compacted list every cycle; with the camera
// replacing textures every frame, the plant keeps them in 64 weight buckets (a factor 2^(1/3) wide each,
// highest first) instead, so a cycle walks them in weight order without a sort per frame.
class Plant {
 public:
  static constexpr uint32_t kBuckets = 64;

  Plant(const PlantOptions& o, uint64_t seed) : o_(o), seed_(seed), buckets_(kBuckets) {
    slots_.resize(o.visible);
    for (uint32_t i = 0; i < o.visible; ++i) place(i, make_texture(seed_, next_id_++));
  }

  RunStats run(stream::AdaptiveController ctl, double load_time_s, const std::string& name) {
    RunStats st;
    st.name = name;
    double t = 0, replace_debt = 0;
    size_t next_switch = 0;
    uint64_t frame = 0;
    while (t < o_.duration_s) {
      // Camera: a view switch replaces everything; otherwise textures are replaced at a steady rate unless
      // the camera is paused.
      if (next_switch < 4 && t >= o_.switches_s[next_switch]) {
        for (uint32_t i = 0; i < slots_.size(); ++i) replace(i);
        ++next_switch;
      } else if (!paused(t)) {
        replace_debt += o_.replace_per_s * last_dt_s_;
        for (; replace_debt >= 1.0; replace_debt -= 1.0) {
          replace(static_cast<uint32_t>(hash64(seed_, next_id_ * 2 + 1) % slots_.size()));
        }
      }

      // One streaming cycle with this frame's s and b (Algorithm 1).
      const double s = ctl.load_size_bytes();
      const float b = static_cast<float>(ctl.mip_bias());
      double batch = 0, load_s = 0, pages = 0, mips = 0;
      bool stop = false;
      for (uint32_t k = kBuckets; k-- > 0 && !stop;) {
        if (bucket_floor(k) < o_.tau_px2) break;  // τ cut-off
        for (uint32_t slot : buckets_[k]) {
          Texture& tex = slots_[slot];
          if (tex.final) continue;
          int level;
          if (tex.resident < 0) {
            level = std::max(0, tex.e - 2);  // the 4x4 mip
          } else if (tex.desired + b < static_cast<float>(tex.resident)) {
            level = tex.resident - 1;
          } else {
            continue;
          }
          if (batch > s || load_s > load_time_s) {  // Algorithm 1's test, before each load
            stop = true;
            break;
          }
          const double bytes = mip_bytes(tex.e, level);
          batch += bytes;
          load_s += o_.load_us_per_mip * 1e-6 + bytes / (o_.load_gb_per_s * 1e9);
          const double pg = bytes / o_.page_bytes;
          pages += pg;
          tex.resident = level;
          tex.final = level == 0;
          ++mips;
        }
      }
      // Bound blocks stay bound after their texture leaves the view (the seed's cache recycles whole layers
      // only when it runs out), so the cache fills up and every later bind is dearer.
      cached_pages_ = std::min(cached_pages_ + pages, o_.cache_pages);

      // The frame pays for it.
      Rng noise(hash64(seed_ ^ 0x5bd1e995ull, frame));
      double ms = o_.base_ms + o_.density_swing_ms * std::sin(2 * M_PI * t / 23.0) + noise.uniform(-1, 1) * o_.noise_ms;
      if (noise.chance(o_.stutter_per_frame)) ms += noise.uniform(o_.stutter_min_ms, o_.stutter_max_ms);
      ms += o_.upload_ms_per_mb * batch / 1e6;
      ms += o_.bind_ms_per_page * pages * (1 + pages / o_.bind_batch_pages) *
            (1 + cached_pages_ / o_.bind_resident_pages);
      const double dt_s = ms / 1e3;
      ctl.on_frame(dt_s, batch);

      st.latency_ms.push_back(ms);
      st.bytes += batch;
      st.mips += mips;
      st.sum_s_mb += s / 1e6;
      st.sum_b += static_cast<double>(b);
      st.max_tw_ms = std::max(st.max_tw_ms, ctl.weighted_latency_s() * 1e3);
      ++st.frames;
      t += dt_s;
      last_dt_s_ = dt_s;
      ++frame;
    }
    st.seconds = t;
    return st;
  }

 private:
  static double bucket_floor(uint32_t k) { return std::exp2(static_cast<double>(k) / 3.0); }
  static uint32_t bucket_of(float weight) {
    const double k = std::floor(3.0 * std::log2(std::max(1.0, static_cast<double>(weight))));
    return static_cast<uint32_t>(std::min(k, static_cast<double>(kBuckets - 1)));
  }
  bool paused(double t) const {
    for (double p : o_.pauses_s) {
      if (t >= p && t < p + o_.pause_length_s) return true;
    }
    return false;
  }
  void place(uint32_t slot, Texture tex) {
    tex.bucket = bucket_of(tex.weight);
    tex.pos = static_cast<uint32_t>(buckets_[tex.bucket].size());
    buckets_[tex.bucket].push_back(slot);
    slots_[slot] = tex;
  }
  // The texture in `slot` leaves the view and a new one enters.
  void replace(uint32_t slot) {
    const Texture& old = slots_[slot];
    auto& bucket = buckets_[old.bucket];
    const uint32_t moved = bucket.back();
    bucket[old.pos] = moved;
    slots_[moved].pos = old.pos;
    bucket.pop_back();
    place(slot, make_texture(seed_, next_id_++));
  }

  PlantOptions o_;
  uint64_t seed_;
  uint64_t next_id_ = 0;
  std::vector<Texture> slots_;
  std::vector<std::vector<uint32_t>> buckets_;
  double cached_pages_ = 0;
  double last_dt_s_ = 0.005;
};

stream::AdaptiveController make_controller(stream::ControllerParams p) {
  auto c = stream::AdaptiveController::create(p);
  if (!c) {
    std::fprintf(stderr, "controller: %s\n", c.error().message.c_str());
    std::exit(2);
  }
  return std::move(*c);
}

void print_row(const RunStats& r) {
  const double mbps = r.bytes / 1e6 / r.seconds;
  std::printf("%-12s %7llu %8.2f %8.2f %9.2f %9.2f %8.3f %6.2f %9.2f %9.0f\n", r.name.c_str(),
              static_cast<unsigned long long>(r.frames), percentile(r.latency_ms, 50), mean(r.latency_ms),
              *std::max_element(r.latency_ms.begin(), r.latency_ms.end()), r.max_tw_ms,
              r.sum_s_mb / static_cast<double>(r.frames), r.sum_b / static_cast<double>(r.frames), mbps,
              r.mips / r.seconds);
}

struct Comparison {
  double base_max_ms, max_ms, reduction, ratio;
};
Comparison compare(const RunStats& base, const RunStats& adaptive) {
  Comparison c;
  c.base_max_ms = *std::max_element(base.latency_ms.begin(), base.latency_ms.end());
  c.max_ms = *std::max_element(adaptive.latency_ms.begin(), adaptive.latency_ms.end());
  c.reduction = 1.0 - c.max_ms / c.base_max_ms;
  c.ratio = (adaptive.bytes / adaptive.seconds) / (base.bytes / base.seconds);
  return c;
}

// --plant key=value: one PlantOptions field (for sensitivity runs); false with a message on a bad one.
bool set_plant_option(PlantOptions& po, const std::string& kv) {
  struct Field {
    const char* name;
    double* value;
  };
  double visible = static_cast<double>(po.visible);
  const Field fields[] = {{"replace_per_s", &po.replace_per_s},
                          {"base_ms", &po.base_ms},
                          {"density_swing_ms", &po.density_swing_ms},
                          {"noise_ms", &po.noise_ms},
                          {"stutter_per_frame", &po.stutter_per_frame},
                          {"stutter_max_ms", &po.stutter_max_ms},
                          {"upload_ms_per_mb", &po.upload_ms_per_mb},
                          {"bind_ms_per_page", &po.bind_ms_per_page},
                          {"bind_batch_pages", &po.bind_batch_pages},
                          {"bind_resident_pages", &po.bind_resident_pages},
                          {"cache_pages", &po.cache_pages},
                          {"load_us_per_mip", &po.load_us_per_mip},
                          {"load_gb_per_s", &po.load_gb_per_s},
                          {"duration_s", &po.duration_s},
                          {"visible", &visible}};
  const size_t eq = kv.find('=');
  const std::string key = kv.substr(0, eq);
  char* end = nullptr;
  const double v = eq == std::string::npos ? 0.0 : std::strtod(kv.c_str() + eq + 1, &end);
  for (const auto& f : fields) {
    if (key != f.name) continue;
    if (eq == std::string::npos || !end || *end != '\0' || !std::isfinite(v) || v <= 0) {
      std::fprintf(stderr, "controller: --plant %s: the value must be a positive number\n", kv.c_str());
      return false;
    }
    *f.value = v;
    po.visible = static_cast<size_t>(visible);
    return po.visible > 0;
  }
  std::fprintf(stderr, "controller: --plant %s: unknown key\n", kv.c_str());
  return false;
}

struct ControllerArgs {
  bool quick = false;
  uint64_t seed = 1;
  std::vector<std::string> plant;  // key=value, in the order given
  bool loop_only = false;
};

int run_controller(const ControllerArgs& args) {
  const bool quick = args.quick;
  const uint64_t seed = args.seed;
  PlantOptions po;
  const bool skip_stress = args.loop_only;
  for (const std::string& kv : args.plant) {
    if (!set_plant_option(po, kv)) return 2;
  }

  Stopwatch total;

  // (a) stability
  controller_stress::StressOptions so;
  so.sequences = skip_stress ? 0 : 1000000;
  so.seed = seed;
  Stopwatch sw;
  const auto stress = controller_stress::run_stress(so);
  std::printf(
      "stress: %llu sequences, %llu steps (%llu inputs rejected as NaN/inf/negative/absurd), %llu bad outputs, %.1f "
      "s\n",
      static_cast<unsigned long long>(stress.sequences), static_cast<unsigned long long>(stress.steps),
      static_cast<unsigned long long>(stress.inputs_rejected), static_cast<unsigned long long>(stress.bad_outputs),
      sw.seconds());
  if (!stress.first_failure.empty()) std::printf("  first failure: %s\n", stress.first_failure.c_str());
  const uint64_t drift_steps = skip_stress ? 0 : quick ? 10000000ull : 100000000ull;
  sw.reset();
  const auto drift = controller_stress::run_drift(drift_steps, seed);
  std::printf(
      "drift: %llu steps, %llu checkpoints: max |t_wa - exact| = %.3g s, max |t_b - exact| = %.3g s "
      "(a double running sum: %.3g s), %.1f s\n",
      static_cast<unsigned long long>(drift.steps), static_cast<unsigned long long>(drift.checkpoints),
      drift.max_twa_error_s, drift.max_tb_error_s, drift.max_naive_twa_error_s, sw.seconds());
  const bool drift_ok = drift.max_twa_error_s <= 1e-12 && drift.max_tb_error_s <= 1e-12;

  // (b) closed loop
  const double load_time_s = 0.016;  // Table 2
  std::printf("\nclosed loop: %.1f s fly-through, %zu visible textures, seed %llu, load time %.0f ms, beta 8\n",
              po.duration_s, po.visible, static_cast<unsigned long long>(seed), load_time_s * 1e3);
  std::printf("%-12s %7s %8s %8s %9s %9s %8s %6s %9s %9s\n", "run", "frames", "med ms", "avg ms", "max ms", "max tw",
              "avg s MB", "avg b", "MB/s", "mips/s");
  stream::ControllerParams none;
  none.mode = ControllerMode::kNone;
  stream::ControllerParams seed16;
  seed16.mode = ControllerMode::kSeed;
  const RunStats base = Plant(po, seed).run(make_controller(none), load_time_s, "baseline");
  print_row(base);
  RunStats at16;
  for (double alpha_ms : {12.0, 14.0, 16.0, 18.0}) {
    stream::ControllerParams p;
    p.mode = ControllerMode::kSeed;
    p.alpha_s = alpha_ms / 1e3;
    char name[32];
    std::snprintf(name, sizeof name, "alpha=%.0fms", alpha_ms);
    RunStats r = Plant(po, seed).run(make_controller(p), load_time_s, name);
    print_row(r);
    if (alpha_ms == 16.0) at16 = std::move(r);
  }
  // Mode auto (the default): no α; its target comes from the plant's measured latency without streaming.
  stream::ControllerParams auto_params;
  auto_params.mode = ControllerMode::kAuto;
  const RunStats automatic = Plant(po, seed).run(make_controller(auto_params), load_time_s, "auto");
  print_row(automatic);
  const Comparison c16 = compare(base, at16);
  std::printf(
      "\nalpha=16ms vs baseline: max frame latency %.1f -> %.1f ms (reduction %.1f %%, goal >= 80 %%), "
      "MB/s ratio %.2f (goal >= 0.5)\n",
      c16.base_max_ms, c16.max_ms, 100 * c16.reduction, c16.ratio);
  const Comparison ca = compare(base, automatic);
  std::printf("auto vs baseline: max frame latency %.1f -> %.1f ms (reduction %.1f %%), MB/s ratio %.2f\n",
              ca.base_max_ms, ca.max_ms, 100 * ca.reduction, ca.ratio);

  if (!quick) {
    // How much the figures depend on the seed (the maximum is one frame) and on the plant.
    std::printf("\nsensitivity (alpha=16ms vs baseline):\n");
    for (uint64_t sd = seed + 1; sd <= seed + 4; ++sd) {
      const Comparison c = compare(Plant(po, sd).run(make_controller(none), load_time_s, "baseline"),
                                   Plant(po, sd).run(make_controller(seed16), load_time_s, "alpha=16ms"));
      std::printf("  seed %-3llu            max %7.1f -> %6.1f ms  reduction %5.1f %%  MB/s ratio %.2f\n",
                  static_cast<unsigned long long>(sd), c.base_max_ms, c.max_ms, 100 * c.reduction, c.ratio);
    }
    PlantOptions cheap = po;  // binds 10x cheaper and barely growing: streaming hardly hurts the baseline
    cheap.bind_ms_per_page = 0.1;
    cheap.bind_batch_pages = 100;
    cheap.bind_resident_pages = 1e9;
    const Comparison c = compare(Plant(cheap, seed).run(make_controller(none), load_time_s, "baseline"),
                                 Plant(cheap, seed).run(make_controller(seed16), load_time_s, "alpha=16ms"));
    std::printf("  cheap-bind plant    max %7.1f -> %6.1f ms  reduction %5.1f %%  MB/s ratio %.2f\n", c.base_max_ms,
                c.max_ms, 100 * c.reduction, c.ratio);
  }
  std::printf("drift %s; %.1f s total\n", drift_ok ? "none" : "FOUND", total.seconds());
  Summary()
      .add("stress_sequences", static_cast<double>(stress.sequences))
      .add("bad_outputs", static_cast<double>(stress.bad_outputs + (drift_ok ? 0 : 1)))
      .add("max_latency_reduction", c16.reduction)
      .add("mbps_ratio", c16.ratio)
      .add("auto_max_latency_reduction", ca.reduction)
      .add("auto_mbps_ratio", ca.ratio)
      .print();
  return stress.bad_outputs == 0 && drift_ok ? 0 : 1;
}

std::function<int()> define_controller(CLI::App& app) {
  auto a = std::make_shared<ControllerArgs>();
  app.add_flag("--quick", a->quick, "the short run");
  app.add_option("--seed", a->seed, "seed of the stress sequences");
  app.add_option("--plant", a->plant, "key=value: a closed-loop plant setting (repeatable)")
      ->expected(1)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  app.add_flag("--loop-only", a->loop_only, "only the closed loop, no stress sequences");
  return [a] { return run_controller(*a); };
}

}  // namespace

TEXSTREAM_BENCH_COMMAND(controller, "adaptive controller: stress sequences, drift, closed-loop plant (Eq. 4-7)",
                        define_controller);

}  // namespace texstream::bench
