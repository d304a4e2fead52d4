#include "pages_gpu.hpp"

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "texstream/render/measure/reference_frames.hpp"

namespace texstream::bench {

namespace fs = std::filesystem;

namespace {

fs::path bin_dir() { return fs::canonical("/proc/self/exe").parent_path(); }

int run_logged(const std::string& cmd, const fs::path& log) {
  const int rc = std::system((cmd + " > '" + log.string() + "' 2>&1").c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace

GpuSeams gpu_seams(const fs::path& work, const std::string& device, bool quick) {
  GpuSeams r;
  const fs::path bin = bin_dir();
  if (!fs::exists(bin / "texstream-render") || !fs::exists(bin / "texstream-gen")) {
    r.why = "texstream-render or texstream-gen is not next to texstream-bench";
    return r;
  }
  fs::create_directories(work);
  const fs::path scene = work / "city";
  const std::string gen = (bin / "texstream-gen").string() + " --out " + scene.string() +
                          " --textures 300 --seed 11 --format rgba8 --ground pages --force";
  if (run_logged(gen, work / "gen.log") != 0) {
    r.why = "texstream-gen failed: see " + (work / "gen.log").string();
    return r;
  }
  const uint32_t width = quick ? 320 : 640, height = quick ? 180 : 360;
  const int frames = quick ? 8 : 0;  // 0: the whole path
  auto render = [&](const std::string& name, const std::string& sets) {
    const std::string cmd =
        (bin / "texstream-render").string() + " --set render.device=" + device + " --set scene.dir=" + scene.string() +
        " --set render.output_dir=" + (work / name).string() + " --set render.width_px=" + std::to_string(width) +
        " --set render.height_px=" + std::to_string(height) + " --set render.frames=" + std::to_string(frames) +
        " --set render.frame_time_ms=1000 --set render.lockstep=true"
        " --set render.write_every_frames=1 --set controller.mode=none"
        " --set stream.colormap_blend=false --set render.load_wanted_before_drawing=true" +
        sets;
    return run_logged(cmd, work / (name + ".log"));
  };
  if (render("pages", "") != 0 || render("reference", " --set pages.reference=true") != 0) {
    r.why = "texstream-render failed: see " + work.string() + "/{pages,reference}.log";
    return r;
  }
  const auto summary = nlohmann::json::parse(slurp(work / "pages" / "summary.json"), nullptr, false);
  if (summary.is_object()) {
    r.device = summary.value("device", "");
    r.frames = summary.value("frames", uint64_t{0});
  }
  auto a = render::ReferenceFrames::open(work / "pages", width, height);
  auto e = render::ReferenceFrames::open(work / "reference", width, height);
  if (!a.ok() || !e.ok()) {
    r.why = "frames unreadable: " + (a.ok() ? e.error().message : a.error().message);
    return r;
  }
  for (uint64_t i = 0; i < r.frames; ++i) {
    auto fa = a->frame(i);
    auto fe = e->frame(i);
    if (!fa.ok() || !fe.ok()) {
      r.why = "frame " + std::to_string(i) + " unreadable";
      return r;
    }
    const auto* pa = reinterpret_cast<const unsigned char*>(fa->pixels.data());
    const auto* pe = reinterpret_cast<const unsigned char*>(fe->pixels.data());
    for (size_t k = 0; k < size_t{width} * height * 4; ++k) {
      if (k % 4 == 3) continue;
      r.max_abs_diff = std::max(r.max_abs_diff, static_cast<double>(std::abs(int{pa[k]} - int{pe[k]})));
    }
  }
  r.ran = true;
  return r;
}

}  // namespace texstream::bench
