#include "path_runner.hpp"

#include <fcntl.h>
#include <sys/wait.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <fstream>

#include "bench_util.hpp"
#include "path_analysis.hpp"
#include "texstream/common/child_process.hpp"

namespace fs = std::filesystem;

namespace texstream::bench {

namespace {
constexpr const char* kSystemPython = "/usr/bin/python3";
// Cache sizing for the all-resident runs: the address space of one sparse image on lavapipe is 2 GiB and an
// image has at most 2048 layers (DESIGN "Lavapipe facts").
constexpr uint64_t kMaxLayers = 2048;
constexpr uint64_t kMaxCacheBytes = 2ull << 30;
}  // namespace

CameraPath section_around_first_cut(const CameraPath& path, double before_s, double after_s) {
  const auto cuts = cut_times(path);
  const double t0 = cuts.empty() ? 0.0 : std::max(0.0, cuts.front() - before_s);
  const double t1 = std::min(path.duration_s(), cuts.empty() ? before_s + after_s : cuts.front() + after_s);
  return path_section(path, t0, t1);
}

int run_process(const std::vector<std::string>& argv, const fs::path& log) {
  SpawnOptions options;
  options.fds = {SpawnFd::open(1, log.string(), O_WRONLY | O_CREAT | O_TRUNC, 0644), SpawnFd::dup2(1, 2)};
  const Result<pid_t> pid = spawn_process(argv, options);
  if (!pid) return -1;
  const std::optional<ExitStatus> e = wait_process(*pid);
  if (!e) return -1;
  if (e->exited) return e->code;
  return e->signal != 0 ? 128 + e->signal : -1;
}

int run_python(const fs::path& script, const std::vector<std::string>& args, const fs::path& log) {
  const bool system_python = fs::exists(kSystemPython);
  std::vector<std::string> argv{system_python ? kSystemPython : "/usr/bin/env"};
  if (!system_python) argv.push_back("python3");
  argv.push_back(script.string());
  argv.insert(argv.end(), args.begin(), args.end());
  return run_process(argv, log);
}

std::vector<std::string> ResidentCache::sets() const {
  return {"cache.layer_extent_px=" + std::to_string(layer_extent), "cache.layers=" + std::to_string(layers),
          "cache.memory_bytes=" + std::to_string(memory_bytes)};
}

ResidentCache resident_cache(const render::SceneData& scene) {
  ResidentCache c;
  std::vector<uint64_t> per_extent(32, 0);
  uint32_t bytes_per_block = 0;
  for (const scene::TextureRecord& s : scene.texture_records()) {  // the records as they are: no copy of the table
    uint64_t e = 4;
    while (e < std::max(s.width, s.height)) e *= 2;
    c.layer_extent = std::max(c.layer_extent, e);
    ++per_extent[static_cast<size_t>(std::log2(static_cast<double>(e)))];
    // The format was checked when the scene was opened.
    const TexelFormat format = texel_format_from_raw(s.format).value_or(TexelFormat::kRgba8);
    bytes_per_block = is_block_compressed(format) ? block_bytes(format) : 64;  // a 4x4 block
  }
  for (size_t k = 0; k < per_extent.size(); ++k) {
    if (!per_extent[k]) continue;
    const uint64_t e = uint64_t{1} << k;
    const uint64_t per_layer = (c.layer_extent / e) * (c.layer_extent / e);
    c.layers += (per_extent[k] + per_layer - 1) / per_layer;
  }
  // Every level of every layer bound in full, counted in 64 KiB sparse pages (the standard sparse block
  // size; lavapipe has no mip tail, so each small level takes a page of its own): an upper bound of what the
  // preload binds, since pages shared between small regions are counted once per layer here anyway.
  constexpr uint64_t kPageBytes = 64u << 10;
  uint64_t pages_per_layer = 0;
  for (uint64_t e = c.layer_extent; e >= 1; e /= 2) {
    const uint64_t blocks = ((e + 3) / 4) * ((e + 3) / 4);
    pages_per_layer += std::max<uint64_t>(1, (blocks * bytes_per_block + kPageBytes - 1) / kPageBytes);
  }
  c.memory_bytes = std::max<uint64_t>(c.layers * pages_per_layer * kPageBytes, 64ull << 20);
  if (c.layers > kMaxLayers) {
    c.error = "the scene needs " + std::to_string(c.layers) + " cache layers of " + std::to_string(c.layer_extent) +
              " px to be resident at once; a sparse image has at most " + std::to_string(kMaxLayers);
  } else if (c.memory_bytes > kMaxCacheBytes) {
    c.error = "the scene needs " + std::to_string(c.memory_bytes >> 20) +
              " MiB of cache to be resident at once; "
              "the sparse address space is " +
              std::to_string(kMaxCacheBytes >> 20) + " MiB";
  }
  return c;
}

std::vector<std::string> reference_sets(ReferenceMode mode) {
  return {mode == ReferenceMode::kPreload ? "render.preload_all=true" : "render.load_wanted_before_drawing=true",
          "render.lockstep=true",
          "render.write_every_frames=1",
          "controller.mode=none",
          "stream.colormap_blend=false",
          "stream.fade_ms=0"};
}

std::vector<std::string> path_run_sets(const fs::path& scene, const fs::path& path_file, double frame_time_s,
                                       uint32_t width, uint32_t height) {
  return {"scene.dir=" + scene.string(), "render.camera_path=" + path_file.string(), "render.frames=0",
          "render.frame_time_ms=" + std::to_string(frame_time_s * 1e3), "render.width_px=" + std::to_string(width),
          "render.height_px=" + std::to_string(height), "render.write_every_frames=0",
          // Real time: frame N starts no earlier than N frame times in. Without it a renderer that happens to
          // draw slower gets more wall time, so more streaming, per frame of the path, and its image error
          // looks better for being slow (measured: 12 vs 16 ms frames decided ∫MSE ratios on lavapipe).
          "render.pace_frames=true"};
}

RenderOutcome run_renderer(const RenderRun& run) {
  RenderOutcome out;
  std::error_code ec;
  fs::remove_all(run.dir, ec);
  fs::create_directories(run.dir, ec);
  if (ec) {
    out.failure = run.dir.string() + ": " + ec.message();
    return out;
  }
  std::vector<std::string> argv{
      (run.bin / (run.in_process ? "texstream-render-inprocess" : "texstream-render")).string()};
  if (!run.config.empty()) argv.insert(argv.end(), {"--config", run.config.string()});
  argv.insert(argv.end(), {"--set", "render.output_dir=" + run.dir.string()});
  for (const std::string& s : run.sets) argv.insert(argv.end(), {"--set", s});
  {
    std::ofstream cmd(run.dir / "command.txt");
    for (const std::string& a : argv) cmd << a << (a.rfind("--", 0) == 0 ? " " : " \\\n  ");
    cmd << "\n";
  }
  Stopwatch sw;
  out.exit_code = run_process(argv, run.dir / "log.txt");
  out.wall_s = sw.seconds();
  if (out.exit_code != 0) {
    out.failure = "exit code " + std::to_string(out.exit_code) + ", see " + (run.dir / "log.txt").string();
    return out;
  }
  auto frames = render::read_frame_log(run.dir / "frames.csv");
  if (!frames) {
    out.failure = frames.error().message;
    return out;
  }
  out.frames = std::move(frames).value();
  return out;
}

}  // namespace texstream::bench
