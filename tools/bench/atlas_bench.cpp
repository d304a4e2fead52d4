// texstream-bench atlas: streaming a city with one texture per mesh against the same city packed into texture
// atlases (seed 000 §3.1; its Tables 3 and 4 compare Berlin (atlas) with Berlin).
//   1. generates a city (texstream-gen, BC1) and packs it (texstream-atlas, 512 px atlases): textures, atlases,
//      fill, bytes on disk;
//   2. renders the same camera path with the default policy on both scenes (the path advances
//      render.frame_time_ms per frame; the GPU profile also paces frames to it, like a display), from local files and
//      from a slow origin (storage.slow_latency_ms per read, jittered, the server's slow-storage emulation): MB/s
//      and mip/s as the seed's tables, requests, frame latency (mean, p99, max), the weighted mip deficit
//      integrated over the run (what the view wanted and did not have, frames.csv), bytes never displayed.
// --quick: 2,000 textures, 320x180, the first 150 frames (within 60 s on 2 cores); default: 20,000 textures,
// 640x360, the whole path. --device gpu uses config/gpu.toml at 1920x1080. Ratios are plain ÷ atlas (> 1: the atlas is
// better for a time or an error, worse for bytes). Last line: summary: textures=N atlases=A fill=F bytes_ratio=…
// requests_ratio=… deficit_ratio_local=…
//            deficit_ratio_slow=… max_latency_ratio_local=… max_latency_ratio_slow=…
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "bench_registry.hpp"
#include "bench_util.hpp"
#include "texstream/common/scene_format.hpp"

namespace texstream::bench {
namespace {
namespace fs = std::filesystem;

struct AtlasBenchOptions {
  bool quick = false;
  uint32_t textures = 0;  // 0: 2,000 with --quick, else 20,000
  std::string device = "lavapipe";
  fs::path out;
  double slow_latency_ms = 4;
};

int run_cmd(const std::string& cmd, const fs::path& log) {
  const int rc = std::system((cmd + " > " + log.string() + " 2>&1").c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

struct Run {
  bool ok = false;
  double path_s = 0;  // virtual time covered
  uint64_t frames = 0;
  double mb = 0;
  uint64_t mips = 0;
  uint64_t requests = 0;
  double latency_median = 0, latency_mean = 0, latency_p99 = 0, latency_max = 0;
  double tw_mean = 0;  // the controller's weighted frame latency t_w (seed 000 Eq. 4), mean over frames
  double deficit = 0;  // ∫ weighted mip deficit dt (level-seconds)
  double wasted = 0;   // fraction of bytes never displayed
};

Run read_run(const fs::path& out) {
  Run r;
  std::ifstream sj(out / "summary.json");
  if (!sj) return r;
  const auto s = nlohmann::json::parse(sj, nullptr, false);
  if (s.is_discarded()) return r;
  r.frames = s.value("frames", 0ull);
  r.mb = s.value("mb_streamed", 0.0);
  r.mips = s.value("mips_streamed", 0ull);
  r.wasted = s.value("wasted_bytes_frac", 0.0);
  if (s.contains("stream")) r.requests = s["stream"].value("requests_sent", 0ull);
  std::ifstream csv(out / "frames.csv");
  std::string line;
  std::getline(csv, line);
  std::vector<std::string> names;
  {
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) names.push_back(c);
  }
  auto col = [&](const char* n) {
    return static_cast<size_t>(std::find(names.begin(), names.end(), n) - names.begin());
  };
  const size_t ct = col("time_s"), cl = col("latency_ms"), cd = col("mip_deficit"), cw = col("tw_ms");
  std::vector<double> lat, tw;
  double prev_t = -1, prev_d = 0;
  while (std::getline(csv, line)) {
    std::vector<std::string> f;
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) f.push_back(c);
    if (f.size() <= std::max({ct, cl, cd, cw})) continue;
    tw.push_back(std::atof(f[cw].c_str()));
    const double t = std::atof(f[ct].c_str()), l = std::atof(f[cl].c_str());
    const double d = f[cd].empty() ? prev_d : std::atof(f[cd].c_str());
    if (prev_t >= 0 && std::isfinite(prev_d)) r.deficit += prev_d * (t - prev_t);
    prev_t = t, prev_d = d;
    lat.push_back(l);
    r.path_s = t;
  }
  if (lat.empty()) return r;
  r.latency_median = percentile(lat, 50);
  r.latency_mean = mean(lat);
  r.tw_mean = mean(tw);
  r.latency_p99 = percentile(lat, 99);
  r.latency_max = *std::max_element(lat.begin(), lat.end());
  r.ok = true;
  return r;
}

uint64_t folder_bytes(const fs::path& dir) {
  uint64_t b = 0;
  std::error_code ec;
  for (const auto& e : fs::recursive_directory_iterator(dir, ec))
    if (e.is_regular_file(ec)) b += e.file_size(ec);
  return b;
}

double ratio(double a, double b) { return b > 0 ? a / b : std::nan(""); }

int run_atlas_bench(const AtlasBenchOptions& o) {
  const fs::path bin = self_dir();
  const fs::path work =
      o.out.empty() ? fs::temp_directory_path() / ("texstream_atlas_bench_" + std::to_string(::getpid())) : o.out;
  std::error_code ec;
  fs::create_directories(work, ec);
  const uint32_t n = o.textures ? o.textures : (o.quick ? 2000 : 20000);
  // TEXSTREAM_CONFIG_DIR overrides the build-time path (a bundle run on another machine: scripts/make_gpu_bundle.sh).
  const char* config_dir = std::getenv("TEXSTREAM_CONFIG_DIR");
  const fs::path profile = fs::path(config_dir && *config_dir ? config_dir : TEXSTREAM_ATLAS_BENCH_CONFIG_DIR) /
                           (o.device == "gpu" ? "gpu.toml" : "lavapipe.toml");
  const fs::path plain = work / "plain", atlas = work / "atlas";
  if (run_cmd((bin / "texstream-gen").string() + " --out " + plain.string() + " --textures " + std::to_string(n) +
                  " --seed 1 --format bc1 --force",
              work / "gen.log") != 0) {
    std::fprintf(stderr, "atlas bench: texstream-gen failed (%s)\n", (work / "gen.log").c_str());
    return 1;
  }
  if (run_cmd((bin / "texstream-atlas").string() + " " + plain.string() + " --out " + atlas.string() +
                  " --atlas-px 512 --force --quiet",
              work / "atlas.log") != 0) {
    std::fprintf(stderr, "atlas bench: texstream-atlas failed (%s)\n", (work / "atlas.log").c_str());
    return 1;
  }
  const auto man = scene::read_manifest(atlas);
  const uint64_t out_textures = man ? man->texture_count : 0;
  std::string atlas_line;
  {
    std::ifstream l(work / "atlas.log");
    std::getline(l, atlas_line);
  }
  std::printf("scene: %u textures (BC1) -> %llu textures after packing; %s\n", n,
              static_cast<unsigned long long>(out_textures), atlas_line.c_str());
  const double fill = [&] {
    const auto at = atlas_line.find("atlas fill ");
    return at == std::string::npos ? std::nan("") : std::atof(atlas_line.c_str() + at + 11) / 100.0;
  }();
  const uint64_t bytes_plain = folder_bytes(plain / "textures"), bytes_atlas = folder_bytes(atlas / "textures");
  std::printf("texture files: %.1f MB one per mesh, %.1f MB atlased\n", static_cast<double>(bytes_plain) / 1e6,
              static_cast<double>(bytes_atlas) / 1e6);

  const std::string size = o.device == "gpu" ? "1920x1080" : o.quick ? "320x180" : "640x360";
  const std::string w = size.substr(0, size.find('x')), h = size.substr(size.find('x') + 1);
  const std::string frames = o.quick ? "150" : "0";
  struct Case {
    const char* storage;
    const char* scene;
    Run run;
  };
  std::vector<Case> cases{{"local", "plain", {}}, {"local", "atlas", {}}, {"slow", "plain", {}}, {"slow", "atlas", {}}};
  for (Case& c : cases) {
    const fs::path scene_dir = std::string(c.scene) == "plain" ? plain : atlas;
    const fs::path out = work / (std::string("run_") + c.storage + "_" + c.scene);
    fs::remove_all(out, ec);
    std::string cmd = (bin / "texstream-render").string() + " --config " + profile.string() +
                      " --set scene.dir=" + scene_dir.string() + " --set render.output_dir=" + out.string() +
                      " --set render.width_px=" + w + " --set render.height_px=" + h +
                      " --set render.frames=" + frames +
                      " --set render.write_every_frames=0 --set render.validation=false";
    if (std::string(c.storage) == "slow") {
      char slow[160];
      std::snprintf(slow, sizeof slow,
                    " --set storage.slow_enabled=true --set storage.slow_latency_ms=%g --set storage.slow_jitter_ms=%g",
                    o.slow_latency_ms, o.slow_latency_ms / 2);
      cmd += slow;
    }
    if (run_cmd(cmd, out.string() + ".log") != 0) {
      std::fprintf(stderr, "atlas bench: a run failed (%s.log)\n", out.c_str());
      return 1;
    }
    c.run = read_run(out);
  }

  // The seed's Tables 3 and 4: frame latency (median, average, max), t_w, Mip/s, MB/s; then ours.
  std::printf(
      "\n| storage | scene | path s | frames | latency median / avg / p99 / max ms | t_w avg ms | Mip/s | MB/s | "
      "MB | requests | ∫ mip deficit | never displayed |\n"
      "|---|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const Case& c : cases) {
    const Run& r = c.run;
    std::printf(
        "| %s | %s | %.1f | %llu | %.1f / %.1f / %.1f / %.1f | %.1f | %.0f | %.2f | %.2f | %llu | %.3f | %.3f |\n",
        c.storage, c.scene, r.path_s, static_cast<unsigned long long>(r.frames), r.latency_median, r.latency_mean,
        r.latency_p99, r.latency_max, r.tw_mean, ratio(static_cast<double>(r.mips), r.path_s), ratio(r.mb, r.path_s),
        r.mb, static_cast<unsigned long long>(r.requests), r.deficit, r.wasted);
  }
  const Run &lp = cases[0].run, &la = cases[1].run, &sp = cases[2].run, &sa = cases[3].run;
  std::printf(
      "\nsummary: textures=%u atlases=%llu fill=%.3f bytes_ratio=%.4g requests_ratio=%.4g deficit_ratio_local=%.4g "
      "deficit_ratio_slow=%.4g max_latency_ratio_local=%.4g max_latency_ratio_slow=%.4g\n",
      n, static_cast<unsigned long long>(out_textures), fill, ratio(lp.mb, la.mb),
      ratio(static_cast<double>(lp.requests), static_cast<double>(la.requests)), ratio(lp.deficit, la.deficit),
      ratio(sp.deficit, sa.deficit), ratio(lp.latency_max, la.latency_max), ratio(sp.latency_max, sa.latency_max));
  return 0;
}

std::function<int()> define_atlas(CLI::App& app) {
  auto o = std::make_shared<AtlasBenchOptions>();
  app.add_flag("--quick", o->quick, "the short run");
  app.add_option("--textures", o->textures, "textures of the generated city (default 2,000 quick, 20,000 full)");
  app.add_option("--device", o->device, "lavapipe or gpu (config/gpu.toml)")->check(CLI::IsMember({"lavapipe", "gpu"}));
  app.add_option("--out", o->out, "working folder (scenes, runs)");
  app.add_option("--slow-latency-ms", o->slow_latency_ms, "latency per read of the slow origin")->capture_default_str();
  return [o] { return run_atlas_bench(*o); };
}

}  // namespace

TEXSTREAM_BENCH_COMMAND(atlas, "texture atlases (seed 000 §3.1) against one texture per mesh: bytes, requests, deficit",
                        define_atlas);

}  // namespace texstream::bench
