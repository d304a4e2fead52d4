// texstream-bench path [--quick] [--scene DIR] [--path FILE] [--out DIR] [--config FILE] [--size WxH] [--keep-frames]
//                      [--until S] [--repeat N] [--only NAME,...]
//                      [--reference preload|lockstep-load]
//
// Run time against image error on one camera path (issue 8; seed 000 §4.1-4.5, seed 004 §4.1). Every
// configuration is a texstream-render process (texstream-render-inprocess for the in-process loader) over the
// same path, frame size and frame time; each writes frames.csv (render/frame_log.hpp), which this command
// turns into the seed's tables, the error integrals and the recovery after each cut:
//
//   reference   render.preload_all: every mip of every texture resident before frame 0, lock-step, every
//               frame written, no Eq. 8 blending (a plain mipmapped texture path) — the ground truth the
//               others are compared with (render.reference_dir). A scene that cannot be resident at once
//               (resident_cache) gets render.load_wanted_before_drawing instead: the same frames, each frame's
//               mips loaded before it is drawn; --reference forces either
//   ours        the configuration as given (default: controller.mode = auto, stream.blend = converge)
//   inprocess   ours with the server on a thread of the renderer (prices the process boundary)
//   resident_blend   all resident with the configured blend: must reproduce the reference (converge)
//   baseline    the seed's baseline: controller.mode = none, stream.colormap_blend = false
//   seed        the seed's method: controller.mode = seed (Eq. 4-7, α), stream.blend = seed (Eq. 8)
//   full run only:
//   resident    all resident, no blending: the "no streaming" latency; must reproduce the reference
//   resident_seed_blend   all resident with Eq. 8: the seed blend's own error floor
//   blocking    render.blocking_loads: each visible texture's whole chain before drawing (seed 002 §2)
//   alpha_*     seed mode around the configured α (seed 000 Table 3); beta_*: ours with β = 0, 2, 4
//   lockstep_a/b     lock-step, fixed load size: run twice, every per-frame column must be bit-equal
//
// --quick: a 4 s section of the path around its first cut, 256x144, no sweeps; under 60 s
// on the 2-core lavapipe machine. Ends with `summary: lockstep_identical=... max_latency_ratio=...
// popin_ratio=... integrated_error_ratio=... streaming_overhead=... process_boundary_cost=...
// time_to_detail_ratio=... mip_deficit_ratio=... p99_latency_ratio=... resident_blend_psnr_db=...
// wasted_bytes_frac=...` (issue 25's metrics: docs/design/stream_metrics.md).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "bench_registry.hpp"
#include "bench_util.hpp"
#include "path_analysis.hpp"
#include "path_results.hpp"
#include "path_runner.hpp"
#include "texstream/common/camera_path.hpp"
#include "texstream/common/config.hpp"
#include "texstream/common/config_choice.hpp"
#include "texstream/render/measure/frame_log.hpp"
#include "texstream/render/scene/scene_data.hpp"

namespace fs = std::filesystem;

namespace texstream::bench {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

constexpr uint32_t kFullWidth = 640, kFullHeight = 360;
// Lock-step runs use a fixed load size per cycle (seed 004 §4.1: "a fixed limit of pages per frame"); 1 MB
// is the seed's median s at α = 12-16 ms (Table 3: 0.75-0.96 MB).
constexpr double kLockstepLoadMb = 1.0;

struct Plan {
  fs::path bin, config, scene, path_file, out;
  std::vector<std::string> common;  // --set for every run
};

ConfigRun make(const std::string& name, const std::string& group, const std::string& label,
               std::vector<std::string> sets, bool in_process = false) {
  ConfigRun r;
  r.name = name;
  r.group = group;
  r.label = label;
  r.sets = std::move(sets);
  r.in_process = in_process;
  return r;
}

void execute(const Plan& p, ConfigRun& r, double frame_time_s, const std::vector<double>& cuts) {
  const fs::path dir = p.out / "runs" / r.name;
  RenderRun run{p.bin, p.config, dir, p.common, r.in_process};
  if (r.measured) run.sets.push_back("render.reference_dir=" + (p.out / "runs" / "reference").string());
  run.sets.insert(run.sets.end(), r.sets.begin(), r.sets.end());
  RenderOutcome o = run_renderer(run);
  r.exit_code = o.exit_code;
  r.wall_s = o.wall_s;
  r.failure = o.failure;
  if (!r.failure.empty()) {
    std::fprintf(stderr, "path bench: %s failed: %s\n", r.name.c_str(), r.failure.c_str());
    return;
  }
  std::error_code ec;
  fs::create_directories(p.out / "raw", ec);
  fs::copy_file(dir / "frames.csv", p.out / "raw" / (r.name + ".csv"), fs::copy_options::overwrite_existing, ec);
  r.analysis = analyse_run(o.frames, frame_time_s, cuts);
  r.wasted_bytes_frac = kNaN;
  std::ifstream summary_file(dir / "summary.json");
  const nlohmann::json summary = nlohmann::json::parse(summary_file, nullptr, false);
  if (summary.is_object() && summary.contains("wasted_bytes_frac") && summary["wasted_bytes_frac"].is_number())
    r.wasted_bytes_frac = summary["wasted_bytes_frac"].get<double>();
  std::printf("  %-14s %5.1f s  latency median %6.2f ms max %7.2f ms  PSNR median %6.2f dB  ∫MSE %8.1f  pop-in %7.2f\n",
              r.name.c_str(), r.wall_s, r.analysis.latency_ms.median, r.analysis.latency_ms.max,
              r.analysis.psnr_db.median, r.analysis.integrated_mse, r.analysis.max_popin_mse);
  std::fflush(stdout);
}

std::string fmt_num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}
std::string fmt_name(const std::string& prefix, double v) { return prefix + fmt_num(v); }

// The 1-minute load average (first field of /proc/loadavg), or "?".
std::string load_average() {
  std::ifstream in("/proc/loadavg");
  std::string first;
  return in >> first ? first : std::string("?");
}

struct PathArgs {
  bool quick = false;
  bool keep_frames = false;
  std::string scene, path, out, config, size;  // empty: the default
  double until_s = 0;                          // --until: the first this many seconds of the path (0: all)
  unsigned repeat = 1;                         // --repeat: ours, baseline and seed this many times, interleaved
  std::vector<std::string> only;               // --only: run just these configurations (and the reference)
  std::string reference;  // kReferencePreload, kReferenceLockstepLoad; empty: preload if the scene fits
};

int run_path(const PathArgs& args) {
  Stopwatch total;
  BenchResults res;
  res.quick = args.quick;
  res.load_before = load_average();
  res.cores = std::thread::hardware_concurrency();
  Plan plan;
  plan.bin = self_dir();
  plan.config = args.config;
  if (plan.config.empty()) {
    // The default device is lavapipe: its profile (seed 000 §4.3: α about twice the latency without streaming).
    const fs::path lavapipe = fs::path(TEXSTREAM_PATH_BENCH_SOURCE_DIR) / "config" / "lavapipe.toml";
    if (fs::exists(lavapipe)) plan.config = lavapipe;
  }
  auto base_config = load_config(plan.config, {});
  if (!base_config) {
    std::fprintf(stderr, "path bench: --config: %s\n", base_config.error().message.c_str());
    return 2;
  }
  const double alpha_ms = base_config->controller.alpha_ms;
  plan.scene = args.scene;
  if (plan.scene.empty()) plan.scene = fs::path(TEXSTREAM_PATH_BENCH_SOURCE_DIR) / "scenes" / "default";
  plan.out = args.out;
  if (plan.out.empty()) plan.out = "out/bench-path";
  std::error_code ec;
  plan.out = fs::absolute(plan.out);
  fs::create_directories(plan.out, ec);
  if (ec) {
    std::fprintf(stderr, "path bench: --out %s: %s\n", plan.out.c_str(), ec.message().c_str());
    return 1;
  }
  auto scene = render::SceneData::load(plan.scene);
  if (!scene) {
    std::fprintf(stderr, "path bench: --scene %s: %s\n", plan.scene.c_str(), scene.error().message.c_str());
    return 2;
  }
  plan.scene = fs::absolute(plan.scene);
  const fs::path source_path = args.path.empty() ? scene->dir / scene->manifest.camera_path : fs::path(args.path);
  auto path = CameraPath::load(source_path);
  if (!path || path->keys().empty()) {
    std::fprintf(stderr, "path bench: --path %s: %s\n", source_path.c_str(),
                 path ? "no keyframes" : path.error().message.c_str());
    return 2;
  }
  // Reference frames by preload when the scene fits the cache at once, else by loading each frame's mips
  // before it is drawn (the same frames, docs/design/reference_frames.md).
  const ResidentCache cache = resident_cache(*scene);
  const bool resident_possible = cache.error.empty();
  ReferenceMode reference = resident_possible ? ReferenceMode::kPreload : ReferenceMode::kLockstepLoad;
  if (!args.reference.empty()) {
    reference = args.reference == kReferencePreload ? ReferenceMode::kPreload : ReferenceMode::kLockstepLoad;
  }
  if (reference == ReferenceMode::kPreload && !resident_possible) {
    std::fprintf(stderr, "path bench: --reference %s is impossible: %s\n", kReferencePreload, cache.error.c_str());
    return 1;
  }
  res.reference_mode = reference == ReferenceMode::kPreload ? kReferencePreload : kReferenceLockstepLoad;

  // The path this bench runs: the whole file, or (--quick) the section around its first cut.
  CameraPath bench_path = *path;
  if (args.until_s > 0) bench_path = path_section(bench_path, 0.0, std::min(args.until_s, bench_path.duration_s()));
  if (res.quick) bench_path = section_around_first_cut(bench_path, kQuickBeforeCutS, kQuickAfterCutS);
  plan.path_file = plan.out / "path.txt";
  {
    std::ofstream f(plan.path_file);
    f << "# texstream-bench path: " << (res.quick ? "quick section of " : "") << source_path.string() << "\n"
      << bench_path.to_text();
    if (!f) {
      std::fprintf(stderr, "path bench: cannot write %s\n", plan.path_file.c_str());
      return 1;
    }
  }
  res.scene = plan.scene;
  res.path_file = source_path;
  res.out = plan.out;
  res.width = res.quick ? kQuickWidth : kFullWidth;
  res.height = res.quick ? kQuickHeight : kFullHeight;
  if (const std::string size = args.size; !size.empty()) {
    unsigned w = 0, h = 0;
    char extra = 0;
    // At least one SSIM window (11 px) per axis; the renderer's own limit is 16.
    if (std::sscanf(size.c_str(), "%ux%u%c", &w, &h, &extra) != 2 || w < 16 || h < 16 || w > 16384 || h > 16384) {
      std::fprintf(stderr, "path bench: --size '%s': expected WxH, 16..16384 each (e.g. 640x360)\n", size.c_str());
      return 2;
    }
    res.width = w;
    res.height = h;
  }
  res.frame_time_s = kPathFrameTimeS;
  res.path_duration_s = bench_path.duration_s();
  res.cuts_s = cut_times(bench_path);
  plan.common = path_run_sets(plan.scene, plan.path_file, res.frame_time_s, res.width, res.height);
  // Every run gets the cache that holds the whole scene when there is one (so the all-resident runs and the
  // streaming runs share it); otherwise the configuration's.
  if (resident_possible) {
    const std::vector<std::string> resident_sets = cache.sets();
    plan.common.insert(plan.common.end(), resident_sets.begin(), resident_sets.end());
  }

  // The configurations, in run order. The reference comes first: everything else is measured against it.
  std::vector<ConfigRun>& runs = res.runs;
  runs.push_back(make("reference", "reference",
                      reference == ReferenceMode::kPreload
                          ? "reference (all resident, lock-step)"
                          : "reference (each frame's mips loaded before it is drawn, lock-step)",
                      reference_sets(reference)));
  runs.back().measured = false;
  runs.push_back(make("ours", "baseline",
                      "ours (as configured: controller " + std::string(choice_name(base_config->controller.mode)) +
                          ", β = " + fmt_num(base_config->controller.beta) + ", blend " +
                          std::string(choice_name(base_config->stream.blend)) + ", fade " +
                          fmt_num(base_config->stream.fade_ms) + " ms " +
                          std::string(choice_name(base_config->stream.fade_when)) + ")",
                      {}));
  // Ratios are taken between neighbours in run order (ours, in-process, resident, baseline), so slow drifts
  // of a shared machine's load affect both sides alike.
  runs.push_back(make("inprocess", "baseline", "ours, server in a thread (no process boundary)", {}, true));
  // All resident with the configured blend: it must reproduce the reference (the converging blend is exact
  // at the wanted level); with the seed's Eq. 8 it keeps an error floor of its own (full run only). Skipped,
  // with a note, when the scene cannot be resident at once.
  if (resident_possible) {
    runs.push_back(make("resident_blend", "baseline",
                        "all textures resident, configured blend (must match the reference)",
                        {"render.preload_all=true"}));
  } else {
    res.notes.push_back("The all-resident runs (resident, resident_blend, resident_seed_blend) were skipped: " +
                        cache.error + ". Ratios that need them are not measured.");
  }
  runs.push_back(
      make("baseline", "baseline", "seed baseline (no adaptive streaming, no colour blending, no fade)",
           {"controller.mode=none", "stream.colormap_blend=false", "stream.fade_ms=0", "stream.levels_in_flight=1"}));
  // The seed's method as published: Eq. 4-7 with the configured α, Eq. 8 blending (seed 000 §3.4, §3.7).
  runs.push_back(make("seed", "baseline", "seed method (Eq. 4-7, α = " + fmt_num(alpha_ms) + " ms, Eq. 8 blend)",
                      {"controller.mode=seed", "stream.blend=seed", "stream.fade_ms=0", "stream.levels_in_flight=1"}));
  // Streaming flat out with ours' request pipeline (stream.levels_in_flight as configured): what the controller
  // and the blend add on top of pipelining (docs/design/pipelined_levels.md). Full run, or by --only.
  if (!res.quick) {
    runs.push_back(make("flat_out", "baseline", "flat out, ours' pipelined levels (no controller, no blend)",
                        {"controller.mode=none", "stream.colormap_blend=false", "stream.fade_ms=0"}));
  }
  if (!res.quick && resident_possible) {
    runs.push_back(make("resident", "baseline", "all textures resident (no streaming, no blending)",
                        {"render.preload_all=true", "stream.colormap_blend=false"}));
    runs.push_back(make("resident_seed_blend", "baseline",
                        "all textures resident, Eq. 8 blend (the seed blend's own error)",
                        {"render.preload_all=true", "stream.blend=seed"}));
  }
  if (!res.quick) {
    runs.push_back(
        make("blocking", "baseline", "blocking loads (whole chains before drawing)", {"render.blocking_loads=true"}));
    // Seed 000 Table 3 sweeps α = 12, 14, 16, 18 ms around its chosen 16 ms: the same ratios around the
    // configured α (0.75, 0.875, [1], 1.125) in mode seed, since a sensible α depends on the device (§4.3);
    // β (0, 2, 4; 8 is ours) in the configured mode.
    for (double f : {0.75, 0.875, 1.125}) {
      const double a = std::round(alpha_ms * f * 10) / 10;
      runs.push_back(make(fmt_name("alpha_", a), "alpha", "seed mode, α = " + fmt_num(a) + " ms",
                          {"controller.mode=seed", "stream.blend=seed", "controller.alpha_ms=" + fmt_num(a)}));
    }
    for (double b : {0.0, 2.0, 4.0}) {
      runs.push_back(make(fmt_name("beta_", b), "beta", "ours, β = " + fmt_num(b), {"controller.beta=" + fmt_num(b)}));
    }
  }
  const std::vector<std::string> lockstep{"render.lockstep=true", "controller.mode=fixed",
                                          "controller.fixed_load_mb=" + fmt_num(kLockstepLoadMb),
                                          "controller.fixed_bias=0"};
  runs.push_back(
      make("lockstep_a", "lockstep", "lock-step, s = " + fmt_num(kLockstepLoadMb) + " MB (run 1)", lockstep));
  runs.push_back(
      make("lockstep_b", "lockstep", "lock-step, s = " + fmt_num(kLockstepLoadMb) + " MB (run 2)", lockstep));
  if (!res.quick) {
    runs.push_back(
        make("lockstep_baseline", "lockstep", "lock-step seed baseline (s = s_max, no blending)",
             {"render.lockstep=true", "controller.mode=none", "stream.colormap_blend=false", "stream.fade_ms=0"}));
  }

  // --repeat: more pairs of the real-time runs whose ratios are the headline, interleaved with the first ones
  // so a drift of the machine's load meets every configuration alike.
  for (unsigned k = 2; k <= args.repeat; ++k) {
    for (const char* name : {"ours", "baseline", "seed"}) {
      const ConfigRun* first = res.find(name);
      if (!first) continue;
      ConfigRun again = *first;
      again.name = std::string(name) + "_" + std::to_string(k);
      again.label = first->label + " (run " + std::to_string(k) + ")";
      runs.push_back(std::move(again));
    }
  }
  if (!args.only.empty()) {
    // A repeat ("ours_2") goes with its configuration ("ours").
    auto configuration = [](const std::string& name) {
      const size_t u = name.find_last_of('_');
      const bool repeat = u != std::string::npos && u + 1 < name.size() &&
                          name.find_first_not_of("0123456789", u + 1) == std::string::npos;
      return repeat ? name.substr(0, u) : name;
    };
    std::erase_if(runs, [&](const ConfigRun& r) {
      return r.name != "reference" &&
             std::find(args.only.begin(), args.only.end(), configuration(r.name)) == args.only.end();
    });
  }
  std::printf("path bench: %s, %zu frames of %ux%u, %zu configurations, output %s\n", plan.scene.c_str(),
              static_cast<size_t>(std::floor(res.path_duration_s / res.frame_time_s)) + 1, res.width, res.height,
              runs.size(), plan.out.c_str());
  for (ConfigRun& r : runs) {
    execute(plan, r, res.frame_time_s, res.cuts_s);
    if (r.name == "reference" && !r.failure.empty()) {
      std::fprintf(stderr, "path bench: without reference frames nothing can be measured\n");
      break;
    }
  }
  const nlohmann::json ref_summary = [&] {
    std::ifstream in(plan.out / "runs" / "reference" / "summary.json");
    return nlohmann::json::parse(in, nullptr, false);
  }();
  res.config_file = plan.config;
  res.device = ref_summary.is_object() ? ref_summary.value("device", std::string("?")) : std::string("?");

  auto get = [&](const std::string& name) -> const RunAnalysis* {
    const ConfigRun* r = res.find(name);
    return r && r->failure.empty() && r->exit_code == 0 ? &r->analysis : nullptr;
  };
  HeadlineRatios& h = res.ratios;
  const RunAnalysis *ours = get("ours"), *resident = get("resident_blend"), *inproc = get("inprocess");
  // baseline ÷ ours (and baseline ÷ seed) per pair of runs made together; the headline is the median.
  for (unsigned k = 1; k <= args.repeat; ++k) {
    const std::string suffix = k == 1 ? "" : "_" + std::to_string(k);
    const RunAnalysis* base = get("baseline" + suffix);
    for (const char* who : {"ours", "seed"}) {
      const RunAnalysis* x = get(who + suffix);
      if (!x || !base) continue;
      const std::string key = std::string(who) == "ours" ? "" : "seed_";
      auto add = [&](const std::string& name, double v) { h.per_pair[key + name].push_back(v); };
      add("max_latency_ratio", headline_ratio(base->latency_ms.max, x->latency_ms.max));
      add("popin_ratio", headline_ratio(base->max_popin_mse, x->max_popin_mse));
      add("integrated_error_ratio", headline_ratio(base->integrated_mse, x->integrated_mse));
      add("time_to_detail_ratio",
          headline_ratio(median_time_to_detail(base->detail), median_time_to_detail(x->detail)));
      add("mip_deficit_ratio", headline_ratio(base->integrated_mip_deficit, x->integrated_mip_deficit));
      add("p99_latency_ratio", headline_ratio(base->p99_latency_ms, x->p99_latency_ms));
    }
  }
  auto median_of = [&](const std::string& key) {
    auto it = h.per_pair.find(key);
    if (it == h.per_pair.end()) return kNaN;
    std::vector<double> known;  // a pair with no comparison (NaN) does not vote
    for (double v : it->second) {
      if (!std::isnan(v)) known.push_back(v);
    }
    return nearest_rank(known, 0.5);
  };
  h.max_latency_ratio = median_of("max_latency_ratio");
  h.popin_ratio = median_of("popin_ratio");
  h.integrated_error_ratio = median_of("integrated_error_ratio");
  h.time_to_detail_ratio = median_of("time_to_detail_ratio");
  h.mip_deficit_ratio = median_of("mip_deficit_ratio");
  h.p99_latency_ratio = median_of("p99_latency_ratio");
  h.streaming_overhead = ours && resident ? headline_ratio(ours->latency_ms.median, resident->latency_ms.median) : kNaN;
  h.process_boundary_cost = ours && inproc ? headline_ratio(ours->latency_ms.median, inproc->latency_ms.median) : kNaN;
  h.resident_blend_psnr_db = resident ? resident->psnr_db.median : kNaN;
  h.wasted_bytes_frac = ours ? res.find("ours")->wasted_bytes_frac : kNaN;
  if (get("lockstep_a") && get("lockstep_b")) {
    auto a = render::read_frame_log(plan.out / "raw" / "lockstep_a.csv");
    auto b = render::read_frame_log(plan.out / "raw" / "lockstep_b.csv");
    if (a && b) {
      h.lockstep_difference = lockstep_difference(*a, *b);
      h.lockstep_identical = h.lockstep_difference.empty();
    } else {
      h.lockstep_difference = (a ? b.error() : a.error()).message;
    }
  } else if (!res.find("lockstep_a") || !res.find("lockstep_b")) {
    h.lockstep_difference = "not run (--only)";
  } else {
    h.lockstep_difference = "a lock-step run failed";
  }
  if (!args.keep_frames) {
    // The reference PNGs are the bulk of the output (one per frame); the report does not need them.
    fs::remove_all(plan.out / "runs" / "reference" / "frames", ec);
  }
  res.bench_wall_s = total.seconds();
  res.load_after = load_average();
  bool plots = false;
  if (auto st = write_results_json(res, plan.out / "results.json"); !st) {
    std::fprintf(stderr, "path bench: %s\n", st.error().message.c_str());
  } else {
    const int rc = run_python(fs::path(TEXSTREAM_PATH_BENCH_SOURCE_DIR) / "tools" / "bench" / "path_report_plots.py",
                              {plan.out.string()}, plan.out / "plots.log");
    plots = rc == 0;
    if (!plots) std::fprintf(stderr, "path bench: plots failed (%d), see %s\n", rc, (plan.out / "plots.log").c_str());
  }
  if (auto st = write_report(res, plan.out / "report.md", plots); !st) {
    std::fprintf(stderr, "path bench: %s\n", st.error().message.c_str());
  }
  std::printf("report: %s (%.0f s)\n", (plan.out / "report.md").c_str(), total.seconds());
  bool all_ok = true;
  for (const ConfigRun& r : runs) all_ok = all_ok && r.failure.empty();
  Summary()
      .add_bool("lockstep_identical", h.lockstep_identical)
      .add("max_latency_ratio", h.max_latency_ratio)
      .add("popin_ratio", h.popin_ratio)
      .add("integrated_error_ratio", h.integrated_error_ratio)
      .add("streaming_overhead", h.streaming_overhead)
      .add("process_boundary_cost", h.process_boundary_cost)
      .add("time_to_detail_ratio", h.time_to_detail_ratio)
      .add("mip_deficit_ratio", h.mip_deficit_ratio)
      .add("p99_latency_ratio", h.p99_latency_ratio)
      .add("resident_blend_psnr_db", h.resident_blend_psnr_db)
      .add("wasted_bytes_frac", h.wasted_bytes_frac)
      .print();
  return all_ok ? 0 : 1;
}

}  // namespace

std::function<int()> define_path(CLI::App& app) {
  auto a = std::make_shared<PathArgs>();
  app.add_flag("--quick", a->quick, "the short run");
  app.add_option("--scene", a->scene, "a generated scene (default: one generated for the run)");
  app.add_option("--path", a->path, "camera path file (default: the scene's)");
  app.add_option("--out", a->out, "folder for runs, report.md and plots");
  app.add_option("--config", a->config, "renderer configuration (default: the bench's)");
  app.add_option("--size", a->size, "frame size WxH");
  app.add_flag("--keep-frames", a->keep_frames, "keep the runs' frames");
  app.add_option("--until", a->until_s, "run only the first this many seconds of the camera path")
      ->check(CLI::PositiveNumber);
  app.add_option("--repeat", a->repeat,
                 "run ours, baseline and seed this many times, interleaved; the ratios are the median over the "
                 "pairs, the report gives their range")
      ->check(CLI::Range(1u, 20u));
  app.add_option("--only", a->only,
                 "run only these configurations (comma-separated names, e.g. ours,baseline,seed); the reference "
                 "always runs")
      ->delimiter(',');
  app.add_option("--reference", a->reference,
                 "how the reference frames are made: preload (every texture resident before frame 0) or "
                 "lockstep-load (each frame's mips loaded before it is drawn); default: preload if the scene fits "
                 "the cache at once")
      ->check(CLI::IsMember({kReferencePreload, kReferenceLockstepLoad}));
  return [a] { return run_path(*a); };
}

TEXSTREAM_BENCH_COMMAND(path, "run time against image error on a camera path: seed tables, baselines, report",
                        define_path);

}  // namespace texstream::bench
