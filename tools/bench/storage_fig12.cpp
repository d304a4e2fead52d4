#include "storage_fig12.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>

#include "bench_util.hpp"
#include "path_analysis.hpp"
#include "path_runner.hpp"
#include "texstream/common/camera_path.hpp"
#include "texstream/render/scene/scene_data.hpp"

namespace fs = std::filesystem;

namespace texstream::bench {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// --quick: a 2 s section around the path's first cut (1 s of the pause before it, 1 s after) at 160x90, so
// that the reference and four link runs fit the storage bench's 60 s budget on the 2-core lavapipe machine.
// The full run takes texstream-bench path --quick's section and size (path_runner.hpp).
constexpr double kQuickFigBeforeCutS = 1.0, kQuickFigAfterCutS = 1.0;
constexpr uint32_t kQuickFigWidth = 160, kQuickFigHeight = 90;

Fig12Row measure(const Fig12Link& link, const RenderOutcome& o, double frame_time_s, const std::vector<double>& cuts) {
  Fig12Row row;
  row.link = link;
  row.failure = o.failure;
  if (!o.failure.empty() || o.frames.empty()) {
    if (row.failure.empty()) row.failure = "no frames";
    return row;
  }
  const RunAnalysis a = analyse_run(o.frames, frame_time_s, cuts);
  row.frames = a.frames;
  row.integrated_mse = a.integrated_mse;
  row.mean_psnr_db = a.psnr_db.avg;
  row.wall_s = o.frames.back().wall_s;
  row.first_mip_ms = kNaN;
  for (const render::FrameRecord& f : o.frames) {
    row.bytes += f.bytes;
    row.mips += f.mips;
    if (f.mips > 0 && std::isnan(row.first_mip_ms)) row.first_mip_ms = f.wall_s * 1000;
  }
  const double s = std::max(row.wall_s, 1e-6);
  row.mb_s = double(row.bytes) / s / 1e6;
  row.mips_s = double(row.mips) / s;
  return row;
}

}  // namespace

const Fig12Row* Fig12Result::find(const std::string& name) const {
  for (const Fig12Row& r : rows)
    if (r.link.name == name) return &r;
  return nullptr;
}

Fig12Result run_fig12(const Fig12Plan& plan) {
  Fig12Result res;
  auto scene = render::SceneData::load(plan.scene);
  if (!scene) {
    res.failure = "scene " + plan.scene.string() + ": " + scene.error().message;
    return res;
  }
  const fs::path source_path = scene->dir / scene->manifest.camera_path;
  auto path = CameraPath::load(source_path);
  if (!path || path->keys().empty()) {
    res.failure = "camera path " + source_path.string() + ": " + (path ? "no keyframes" : path.error().message);
    return res;
  }
  const ResidentCache cache = resident_cache(*scene);
  if (!cache.error.empty()) {
    res.failure = "no reference frames possible: " + cache.error;
    return res;
  }
  const CameraPath section = plan.quick ? section_around_first_cut(*path, kQuickFigBeforeCutS, kQuickFigAfterCutS)
                                        : section_around_first_cut(*path, kQuickBeforeCutS, kQuickAfterCutS);
  res.width = plan.quick ? kQuickFigWidth : kQuickWidth;
  res.height = plan.quick ? kQuickFigHeight : kQuickHeight;
  res.path_s = section.duration_s();
  const std::vector<double> cuts = cut_times(section);
  const fs::path dir = plan.work / "fig12";
  std::error_code ec;
  fs::create_directories(dir, ec);
  const fs::path path_file = dir / "path.txt";
  {
    std::ofstream f(path_file);
    f << "# texstream-bench storage fig12: section of " << source_path.string() << "\n" << section.to_text();
    if (!f) {
      res.failure = "cannot write " + path_file.string();
      return res;
    }
  }
  std::vector<std::string> common = path_run_sets(plan.scene, path_file, kPathFrameTimeS, res.width, res.height);
  const std::vector<std::string> resident = cache.sets();
  common.insert(common.end(), resident.begin(), resident.end());

  const fs::path bin = self_dir();
  RenderRun ref{bin, plan.config, dir / "reference", common};
  const std::vector<std::string> ref_sets = reference_sets(ReferenceMode::kPreload);
  ref.sets.insert(ref.sets.end(), ref_sets.begin(), ref_sets.end());
  const RenderOutcome ref_out = run_renderer(ref);
  if (!ref_out.failure.empty()) {
    res.failure = "reference run: " + ref_out.failure;
    return res;
  }
  res.reference_frames = ref_out.frames.size();

  std::ofstream frames_csv(plan.out / "storage_fig12_frames.csv");
  frames_csv << "link,nominal_bytes_s,frame,time_s,wall_s,mse,psnr_db,ssim,mips,bytes\n";
  for (const Fig12Link& link : plan.links) {
    RenderRun run{bin, plan.config, dir / link.name, common};
    // Real time at a fixed display rate: the path advances with the wall clock, so a slow link shows as
    // frames drawn with coarse mips, not as a slower camera.
    run.sets.insert(run.sets.end(), {"render.reference_dir=" + ref.dir.string(), "render.pace_frames=true",
                                     "storage.origin=" + plan.origin_url});
    if (link.nominal_bytes_s > 0) {
      // The true link cap: one token bucket shared by all of the server's reads (nginx's limit_rate is per
      // response and lets each one's first second go out unthrottled).
      run.sets.insert(run.sets.end(), {"storage.slow_enabled=true",
                                       fmt::format("storage.slow_bandwidth_mb_s={}", link.nominal_bytes_s / 1e6)});
    }
    const RenderOutcome o = run_renderer(run);
    res.rows.push_back(measure(link, o, kPathFrameTimeS, cuts));
    for (const render::FrameRecord& f : o.frames) {
      frames_csv << fmt::format("{},{},{},{:.4f},{:.4f},{:.4f},{:.4f},{:.5f},{},{}\n", link.name, link.nominal_bytes_s,
                                f.index, f.time_s, f.wall_s, f.mse, f.psnr_db, f.ssim, f.mips, f.bytes);
    }
  }
  std::ofstream csv(plan.out / "storage_fig12.csv");
  csv << "link,nominal_bytes_s,frames,integrated_mse,mean_psnr_db,wall_s,bytes,mips,mb_s,mips_s,first_mip_ms,failure\n";
  for (const Fig12Row& r : res.rows) {
    std::string failure = r.failure;  // one quoted CSV field
    std::replace(failure.begin(), failure.end(), '"', '\'');
    csv << fmt::format("{},{},{},{:.4f},{:.4f},{:.4f},{},{},{:.6f},{:.3f},{:.3f},\"{}\"\n", r.link.name,
                       r.link.nominal_bytes_s, r.frames, r.integrated_mse, r.mean_psnr_db, r.wall_s, r.bytes, r.mips,
                       r.mb_s, r.mips_s, r.first_mip_ms, failure);
  }
  return res;
}

}  // namespace texstream::bench
