// results.json and report.md of texstream-bench path.
#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>

#include "path_results.hpp"

namespace texstream::bench {

namespace {

// JSON has no NaN or infinity: not-measured values are null.
nlohmann::json num(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

nlohmann::json stat_json(const Stat3& s) {
  return {{"median", num(s.median)}, {"avg", num(s.avg)}, {"max", num(s.max)}, {"samples", s.samples}};
}

std::string cell(double v, int digits = 2) {
  if (std::isnan(v)) return "–";
  if (std::isinf(v)) return v > 0 ? "∞" : "-∞";
  return fmt::format("{:.{}f}", v, digits);
}

// Seed 000 Tables 3-7: one block of rows per configuration, Median / Average / Max.
std::string seed_table(const std::vector<const ConfigRun*>& runs) {
  std::string t = "| | Median | Average | Max |\n|---|---:|---:|---:|\n";
  for (const ConfigRun* r : runs) {
    t += "| **" + r->label + "** | | | |\n";
    if (!r->failure.empty()) {
      t += "| failed: " + r->failure + " | | | |\n";
      continue;
    }
    const RunAnalysis& a = r->analysis;
    auto row = [&](const char* name, const Stat3& s, int digits) {
      t += fmt::format("| {} | {} | {} | {} |\n", name, cell(s.median, digits), cell(s.avg, digits),
                       cell(s.max, digits));
    };
    row("Frame latency (ms)", a.latency_ms, 2);
    row("t_w latency (ms)", a.tw_ms, 2);
    row("Transfer rate (Mip/s)", a.mips_per_s, 0);
    row("Transfer rate (MB/s)", a.mb_per_s, 2);
    row("Load size s (MB)", a.load_size_mb, 2);
    row("Mipmap bias b", a.mip_bias, 2);
    row("Bound pages", a.bound_pages, 0);
    row("Server RAM cache hit rate", a.server_hit_rate, 3);
    if (r->measured) {
      row("MSE", a.mse, 2);
      row("PSNR (dB)", a.psnr_db, 2);
      row("SSIM", a.ssim, 4);
    }
  }
  return t;
}

// Seconds, or "never" for NaN (a time not reached).
std::string seconds_or_never(double s) { return std::isnan(s) ? std::string("never") : cell(s, 2); }

std::string error_table(const std::vector<ConfigRun>& runs) {
  std::string t =
      "| configuration | p95 latency (ms) | p99 latency (ms) | max latency (ms) | ∫MSE dt (MSE·s) | ∫(1−SSIM) dt (s) | "
      "∫mip deficit dt (levels·s) | never displayed (of bytes streamed) | max pop-in MSE | recovery after each cut (s) "
      "| process "
      "wall (s) |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|\n";
  for (const ConfigRun& r : runs) {
    if (!r.measured) continue;
    if (!r.failure.empty()) {
      t += "| " + r.label + " | failed: " + r.failure + " | | | | | | | | | |\n";
      continue;
    }
    const RunAnalysis& a = r.analysis;
    std::string rec;
    for (const Recovery& v : a.recoveries) {
      rec += (rec.empty() ? "" : ", ") +
             fmt::format("{} ({} dB)", seconds_or_never(v.seconds), cell(v.settled_psnr_db, 1));
    }
    if (rec.empty()) rec = "no cut";
    t += fmt::format("| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n", r.label, cell(a.p95_latency_ms),
                     cell(a.p99_latency_ms), cell(a.latency_ms.max), cell(a.integrated_mse, 1),
                     cell(a.integrated_dssim, 4), cell(a.integrated_mip_deficit, 3),
                     std::isnan(r.wasted_bytes_frac) ? std::string("–") : cell(100.0 * r.wasted_bytes_frac, 1) + " %",
                     cell(a.max_popin_mse, 2), rec, cell(r.wall_s, 1));
  }
  return t;
}

// Where the frames that make the p99 spent their latency, beside every frame's mean (frames.csv's parts).
nlohmann::json parts_json(const LatencyParts& p) {
  return {{"frames", p.frames},      {"latency", num(p.latency)}, {"plan", num(p.plan)},
          {"intake", num(p.intake)}, {"bind", num(p.bind)},       {"record", num(p.record)},
          {"gpu", num(p.gpu)},       {"cycle", num(p.cycle)},     {"mips", num(p.mips)}};
}

std::string parts_table(const std::vector<ConfigRun>& runs) {
  std::string t =
      "| configuration | frames | latency | plan | intake | bind | record | gpu | cycle | mips |\n"
      "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (const ConfigRun& r : runs) {
    if (!r.measured || !r.failure.empty()) continue;
    for (const auto& [what, p] : {std::pair{"slowest 1 %", &r.analysis.slowest}, std::pair{"all", &r.analysis.all}}) {
      t += fmt::format("| {} ({}) | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n", r.label, what, p->frames,
                       cell(p->latency), cell(p->plan), cell(p->intake), cell(p->bind), cell(p->record), cell(p->gpu),
                       cell(p->cycle), cell(p->mips, 0));
    }
  }
  return t;
}

// Time to detail after each cut (path_analysis.hpp, TimeToDetail): one row per measured run, one column per
// cut, "deficit / PSNR" seconds.
std::string detail_table(const std::vector<ConfigRun>& runs, const std::vector<double>& cuts_s) {
  if (cuts_s.empty()) return "The path has no cut.\n";
  std::string t = "| configuration |";
  std::string rule = "|---|";
  for (double c : cuts_s) {
    t += fmt::format(" cut at {:.2f} s: deficit 0 / PSNR (target) |", c);
    rule += "---|";
  }
  t += " median deficit-based (s) |\n" + rule + "---:|\n";
  for (const ConfigRun& r : runs) {
    if (!r.measured || !r.failure.empty()) continue;
    t += "| " + r.label + " |";
    for (size_t i = 0; i < cuts_s.size(); ++i) {
      if (i < r.analysis.detail.size()) {
        const TimeToDetail& d = r.analysis.detail[i];
        t += fmt::format(" {} / {} ({} dB) |", seconds_or_never(d.deficit_s), seconds_or_never(d.psnr_s),
                         cell(d.target_psnr_db, 1));
      } else {
        t += " after the run |";
      }
    }
    const double m = median_time_to_detail(r.analysis.detail);
    t += " " + (std::isinf(m) ? std::string("never") : cell(m, 2)) + " |\n";
  }
  return t;
}

}  // namespace

const ConfigRun* BenchResults::find(const std::string& name) const {
  for (const ConfigRun& r : runs)
    if (r.name == name) return &r;
  return nullptr;
}

Status write_results_json(const BenchResults& r, const std::filesystem::path& file) {
  nlohmann::json j;
  j["scene"] = r.scene.string();
  j["path_file"] = r.path_file.string();
  j["config_file"] = r.config_file.string();
  j["device"] = r.device;
  j["reference_mode"] = r.reference_mode;
  j["notes"] = r.notes;
  j["quick"] = r.quick;
  j["width_px"] = r.width;
  j["height_px"] = r.height;
  j["frame_time_s"] = r.frame_time_s;
  j["path_duration_s"] = r.path_duration_s;
  j["cuts_s"] = r.cuts_s;
  j["bench_wall_s"] = r.bench_wall_s;
  j["cores"] = r.cores;
  j["load_average_before"] = r.load_before;
  j["load_average_after"] = r.load_after;
  const HeadlineRatios& h = r.ratios;
  j["summary"] = {{"lockstep_identical", h.lockstep_identical},
                  {"lockstep_difference", h.lockstep_difference},
                  {"max_latency_ratio", num(h.max_latency_ratio)},
                  {"popin_ratio", num(h.popin_ratio)},
                  {"integrated_error_ratio", num(h.integrated_error_ratio)},
                  {"streaming_overhead", num(h.streaming_overhead)},
                  {"process_boundary_cost", num(h.process_boundary_cost)},
                  {"time_to_detail_ratio", num(h.time_to_detail_ratio)},
                  {"mip_deficit_ratio", num(h.mip_deficit_ratio)},
                  {"p99_latency_ratio", num(h.p99_latency_ratio)},
                  {"resident_blend_psnr_db", num(h.resident_blend_psnr_db)},
                  {"wasted_bytes_frac", num(h.wasted_bytes_frac)}};
  nlohmann::json per_pair = nlohmann::json::object();
  for (const auto& [key, values] : h.per_pair) {
    nlohmann::json v = nlohmann::json::array();
    for (double x : values) v.push_back(num(x));
    per_pair[key] = v;
  }
  j["per_pair"] = per_pair;
  nlohmann::json runs = nlohmann::json::array();
  for (const ConfigRun& c : r.runs) {
    const RunAnalysis& a = c.analysis;
    nlohmann::json rec = nlohmann::json::array();
    for (const Recovery& v : a.recoveries)
      rec.push_back({{"cut_s", v.cut_s}, {"settled_psnr_db", num(v.settled_psnr_db)}, {"seconds", num(v.seconds)}});
    // null: never reached within the segment.
    nlohmann::json detail = nlohmann::json::array();
    for (const TimeToDetail& d : a.detail) {
      detail.push_back({{"cut_s", d.cut_s},
                        {"deficit_s", num(d.deficit_s)},
                        {"psnr_s", num(d.psnr_s)},
                        {"target_psnr_db", num(d.target_psnr_db)}});
    }
    runs.push_back({{"name", c.name},
                    {"group", c.group},
                    {"label", c.label},
                    {"sets", c.sets},
                    {"in_process", c.in_process},
                    {"measured", c.measured},
                    {"exit_code", c.exit_code},
                    {"failure", c.failure},
                    {"wall_s", c.wall_s},
                    {"raw_csv", "raw/" + c.name + ".csv"},
                    {"frames", a.frames},
                    {"frame_latency_ms", stat_json(a.latency_ms)},
                    {"p95_latency_ms", num(a.p95_latency_ms)},
                    {"p99_latency_ms", num(a.p99_latency_ms)},
                    {"latency_parts_ms", {{"slowest_1pct", parts_json(a.slowest)}, {"all", parts_json(a.all)}}},
                    {"tw_ms", stat_json(a.tw_ms)},
                    {"load_size_mb", stat_json(a.load_size_mb)},
                    {"mip_bias", stat_json(a.mip_bias)},
                    {"mips_per_s", stat_json(a.mips_per_s)},
                    {"mb_per_s", stat_json(a.mb_per_s)},
                    {"bound_pages", stat_json(a.bound_pages)},
                    {"server_hit_rate", stat_json(a.server_hit_rate)},
                    {"mse", stat_json(a.mse)},
                    {"psnr_db", stat_json(a.psnr_db)},
                    {"ssim", stat_json(a.ssim)},
                    {"integrated_mse", num(a.integrated_mse)},
                    {"integrated_dssim", num(a.integrated_dssim)},
                    {"max_popin_mse", num(a.max_popin_mse)},
                    {"popin_frames", a.popin_frames},
                    {"recoveries", rec},
                    {"mip_deficit", stat_json(a.mip_deficit)},
                    {"integrated_mip_deficit", num(a.integrated_mip_deficit)},
                    {"wasted_bytes_frac", num(c.wasted_bytes_frac)},
                    {"time_to_detail", detail}});
  }
  j["runs"] = runs;
  std::ofstream out(file);
  out << j.dump(2) << "\n";
  out.close();
  if (!out) return make_error(ErrorCode::kIo, file.string() + ": write failed");
  return ok_status();
}

Status write_report(const BenchResults& r, const std::filesystem::path& file, bool with_plots) {
  const HeadlineRatios& h = r.ratios;
  std::string m;
  m += "# texstream-bench path: run time against image error\n\n";
  m += fmt::format(
      "Scene `{}`, camera path `{}` ({:.2f} s, {} cut(s){}), {}×{} px, {:.2f} ms virtual time per frame, device "
      "**{}**{}. Bench wall time {:.0f} s.\n\n",
      r.scene.string(), r.path_file.string(), r.path_duration_s, r.cuts_s.size(),
      r.cuts_s.empty() ? "" : fmt::format(" at {}", fmt::join(r.cuts_s, " s, ")) + " s", r.width, r.height,
      r.frame_time_s * 1e3, r.device, r.quick ? ", **--quick** (a section of the path, fewer configurations)" : "",
      r.bench_wall_s);
  m += fmt::format(
      "Configuration: `{}` plus the bench's overrides (runs/<configuration>/command.txt has each "
      "command line).\n\n",
      r.config_file.empty() ? std::string("built-in defaults") : r.config_file.string());
  m += fmt::format(
      "Machine: {} cores, 1-minute load average {} before and {} after the bench. Real-time latencies on "
      "a loaded machine are noisy; lock-step figures are not.\n\n",
      r.cores, r.load_before, r.load_after);
  m += "Every streamed frame is compared with the reference frame of the same pose: the scene rendered with every "
       "texture's whole mip chain resident (`render.preload_all`, loaded through the server before frame 0), sampled "
       "at the mip the hardware picks (no streaming clamp, no bias), without colormap blending: a plain "
       "mipmapped texture path. The default blend (stream.blend = converge) fades the colormap out by the levels "
       "still missing, so with every texture resident it draws the reference exactly (resident_blend); the seed's "
       "Eq. 8 (stream.blend = seed) mixes it in by the displayed level even then and keeps an error floor of its "
       "own. "
       "MSE and PSNR are over R, G, B (0–255); SSIM is "
       "Wang et al. 2004 on BT.601 luma (11×11 Gaussian window, σ = 1.5, K1 = 0.01, K2 = 0.03), mean over the "
       "whole frame. ∫MSE dt sums MSE × frame time over the run. Pop-in is the largest MSE between two consecutive "
       "frames while the camera is still (a pause): then every change is refinement (seed 000 Fig. 7). Recovery "
       "after a cut is the virtual time until PSNR is within 1 dB of the PSNR the view settles at (median over the "
       "last 0.5 s before the next cut). The weighted mip deficit of a frame is Σ W·max(0, displayed − wanted) / Σ W "
       "over the textures of the latest visibility list (W its weight, wanted its desired level without the bias, "
       "displayed the finest resident level or the wanted one if coarser; the level count with nothing resident), "
       "on the residency the next frame draws; ∫mip deficit dt sums it × frame time. Time to detail after a cut: "
       "the virtual time until the first frame drawn with deficit ≤ 0.1 levels (on a list read after the cut), and "
       "until PSNR "
       "is within 0.5 dB of the settled PSNR (the target in brackets), \"never\" when not within the segment. "
       "Never displayed: bytes of streamed mips that were never sampled at the wanted (or coarsest resident) level "
       "while resident ÷ bytes streamed (docs/design/stream_metrics.md). Transfer rates are sampled in windows of "
       "0.10423 s of wall time "
       "(seed 000 §4.2). Frame 0 is left out of the latency and t_w statistics (one-time driver costs that every "
       "configuration pays alike). Real-time runs measure latency; the camera advances a fixed virtual time per frame. "
       "Each "
       "frame is copied to host memory and appended to a spill file at the frame (outside its latency); the "
       "comparison with the reference runs after the last frame, so it never hands the server extra time.\n\n";
  if (r.reference_mode != "preload") {
    m += "Reference frames here: `render.load_wanted_before_drawing` instead of the preload (the scene need not be "
         "resident at once): each frame is drawn once with feedback, every mip it samples is loaded to its wanted "
         "level, and only then is it drawn; every pixel samples the preload's mip levels "
         "(docs/design/reference_frames.md).\n\n";
  }
  for (const std::string& note : r.notes) m += "**Note:** " + note + "\n\n";
  m += "## Headline\n\n| quantity | value | meaning |\n|---|---:|---|\n";
  m += fmt::format(
      "| lockstep_identical | {} | two lock-step runs: every non-wall-clock per-frame column bit-equal{} |\n",
      h.lockstep_identical ? "true" : "false",
      h.lockstep_difference.empty() ? "" : " (first difference: " + h.lockstep_difference + ")");
  m += fmt::format("| max_latency_ratio | {} | max frame latency, seed baseline ÷ ours (seed 000: ~8×) |\n",
                   cell(h.max_latency_ratio));
  m += fmt::format("| popin_ratio | {} | largest pop-in MSE, seed baseline ÷ ours (seed 000: ~7× quality) |\n",
                   cell(h.popin_ratio));
  m += fmt::format(
      "| integrated_error_ratio | {} | ∫MSE dt, seed baseline ÷ ours (goal ≥ 1: throttling must not buy "
      "latency with accuracy) |\n",
      cell(h.integrated_error_ratio));
  m += fmt::format(
      "| streaming_overhead | {} | median frame latency, ours ÷ all textures resident (the same "
      "renderer and blending; seed 002: negligible) |\n",
      cell(h.streaming_overhead, 3));
  m += fmt::format("| process_boundary_cost | {} | median frame latency, two processes ÷ server in a thread |\n",
                   cell(h.process_boundary_cost, 3));
  m += fmt::format(
      "| time_to_detail_ratio | {} | median over cuts of the time until the mip deficit is ≤ 0.1 levels, seed baseline "
      "÷ ours "
      "(a \"never\" counts as longest) |\n",
      cell(h.time_to_detail_ratio));
  m += fmt::format("| mip_deficit_ratio | {} | ∫ weighted mip deficit dt, seed baseline ÷ ours |\n",
                   cell(h.mip_deficit_ratio));
  m += fmt::format("| p99_latency_ratio | {} | p99 frame latency, seed baseline ÷ ours |\n", cell(h.p99_latency_ratio));
  m += fmt::format(
      "| resident_blend_psnr_db | {} | median PSNR with every texture resident and the default blend (goal ≥ 60 dB) "
      "|\n",
      cell(h.resident_blend_psnr_db));
  m += fmt::format("| wasted_bytes_frac | {} | ours: bytes streamed for mips never displayed ÷ bytes streamed |\n\n",
                   cell(h.wasted_bytes_frac, 3));

  if (!h.per_pair.empty()) {
    m += "## Ratios per pair of runs (baseline ÷ ours; seed_*: baseline ÷ the seed's method)\n\n"
         "Each pair ran back to back; the headline above is the median. Where the range of ours and the seed's "
         "overlap, or a range straddles 1, the difference is within this machine's noise.\n\n"
         "| ratio | median | min | max | per pair |\n|---|---:|---:|---:|---|\n";
    for (const auto& [key, values] : h.per_pair) {
      std::vector<double> known;
      for (double v : values) {
        if (!std::isnan(v)) known.push_back(v);
      }
      const auto [lo, hi] = known.empty() ? std::pair<double, double>{NAN, NAN}
                                          : std::pair<double, double>{*std::min_element(known.begin(), known.end()),
                                                                      *std::max_element(known.begin(), known.end())};
      std::vector<std::string> cells;
      for (double v : values) cells.push_back(cell(v));
      m += fmt::format("| {} | {} | {} | {} | {} |\n", key, cell(nearest_rank(known, 0.5)), cell(lo), cell(hi),
                       fmt::join(cells, ", "));
    }
    m += "\n";
  }

  auto group = [&](const std::string& g) {
    std::vector<const ConfigRun*> v;
    for (const ConfigRun& c : r.runs)
      if (c.group == g) v.push_back(&c);
    return v;
  };
  m += "## Ours against the baselines (real time)\n\n" + seed_table(group("baseline")) + "\n";
  if (!group("alpha").empty()) {
    m += "## α sweep (seed 000 Tables 3–5: α × 0.75, 0.875, 1.125 of the configured one)\n\n" +
         seed_table(group("alpha")) + "\n";
  }
  if (!group("beta").empty()) m += "## β sweep (seed 000 Table 6)\n\n" + seed_table(group("beta")) + "\n";
  m += "## Lock-step (virtual clock, fixed per-frame budget)\n\n" + seed_table(group("lockstep")) + "\n";
  m += "## Run time against error (one row per configuration)\n\n" + error_table(r.runs) + "\n";
  m += "## Time to detail after each cut (s)\n\n" + detail_table(r.runs, r.cuts_s) + "\n";
  m += "## Where the latency goes (ms, mean over the frames)\n\nThe frames at or above each run's p99 latency "
       "against all its frames (frame 0 left out), by frames.csv's parts: plan (broad phase, draw lists), intake "
       "(completions into the staging ring), bind (the cache's sparse binds), record, gpu (submission to fence: "
       "copies and passes), cycle (list read back, streaming cycle); mips uploaded per frame.\n\n" +
       parts_table(r.runs) + "\n";
  if (with_plots) {
    m += "## Plots\n\n";
    m += "![frame latency, t_w, s and b over time (seed 000 Fig. 6)](plots/fig6_ours.png)\n\n";
    m += "![the seed baseline over time](plots/fig6_baseline.png)\n\n";
    m += "![PSNR against the reference over time](plots/error_over_time.png)\n\n";
    m += "![weighted mip deficit over time](plots/mip_deficit.png)\n\n";
    m += "![p95 frame latency against integrated error: the Pareto view](plots/pareto.png)\n\n";
  } else {
    m += "Plots were not made (python3 with matplotlib failed or is missing; see the bench output).\n\n";
  }
  m += "## Notes\n\nFLIP (NVIDIA's perceptual image difference) is not measured: Debian 12 packages no implementation "
       "of it (`apt-cache search flip` lists only unrelated packages), and the tree takes its libraries from Debian; "
       "NVIDIA's own code (NVlabs/flip) is distributed on PyPI as `flip-evaluator`. Image error here is MSE, PSNR and "
       "SSIM.\n\n";
  m += "## Raw data\n\n`raw/<configuration>.csv`: one row per frame (columns of renderer/include/texstream/render/"
       "measure/frame_log.hpp); `results.json`: everything in this report; `runs/<configuration>/`: each run's "
       "summary.json, "
       "cache.json and log.\n";
  std::ofstream out(file);
  out << m;
  out.close();
  if (!out) return make_error(ErrorCode::kIo, file.string() + ": write failed");
  return ok_status();
}

}  // namespace texstream::bench
