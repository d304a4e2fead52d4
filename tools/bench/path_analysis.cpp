#include "path_analysis.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace texstream::bench {

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// Exact equality that also holds for two NaNs (columns that were not measured in either run).
bool same(double a, double b) {
  if (std::isnan(a) || std::isnan(b)) return std::isnan(a) && std::isnan(b);
  return std::memcmp(&a, &b, sizeof a) == 0;
}
}  // namespace

Stat3 stat3(const std::vector<double>& values) {
  std::vector<double> v;
  v.reserve(values.size());
  for (double x : values)
    if (std::isfinite(x)) v.push_back(x);
  Stat3 s;
  s.samples = v.size();
  if (v.empty()) {
    s.median = s.avg = s.max = kNaN;
    return s;
  }
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  s.median = n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
  double sum = 0;
  for (double x : v) sum += x;
  s.avg = sum / static_cast<double>(n);
  s.max = v.back();
  return s;
}

Rates windowed_rates(const std::vector<render::FrameRecord>& frames, double window_s) {
  Rates r;
  double start = 0, mips = 0, bytes = 0;
  for (const render::FrameRecord& f : frames) {
    mips += static_cast<double>(f.mips);
    bytes += static_cast<double>(f.bytes);
    const double span = f.wall_s - start;
    if (span >= window_s) {
      r.mips_per_s.push_back(mips / span);
      r.mb_per_s.push_back(bytes / 1e6 / span);
      start = f.wall_s;
      mips = bytes = 0;
    }
  }
  return r;
}

Recovery recovery_after_cut(const std::vector<render::FrameRecord>& frames, double cut_s, double segment_end_s,
                            double tolerance_db, double settle_window_s) {
  Recovery r;
  r.cut_s = cut_s;
  r.settled_psnr_db = r.seconds = kNaN;
  std::vector<double> settled;
  for (const render::FrameRecord& f : frames) {
    if (f.time_s >= cut_s && f.time_s < segment_end_s && f.time_s >= segment_end_s - settle_window_s)
      settled.push_back(f.psnr_db);
  }
  r.settled_psnr_db = stat3(settled).median;
  if (std::isnan(r.settled_psnr_db)) return r;
  for (const render::FrameRecord& f : frames) {
    if (f.time_s < cut_s || f.time_s >= segment_end_s || !std::isfinite(f.psnr_db)) continue;
    if (f.psnr_db >= r.settled_psnr_db - tolerance_db) {
      r.seconds = f.time_s - cut_s;
      break;
    }
  }
  return r;
}

TimeToDetail time_to_detail(const std::vector<render::FrameRecord>& frames, double cut_s, double segment_end_s,
                            double frame_time_s) {
  TimeToDetail d;
  d.cut_s = cut_s;
  d.deficit_s = kNaN;
  const Recovery r = recovery_after_cut(frames, cut_s, segment_end_s, kDetailToleranceDb);
  d.psnr_s = r.seconds;
  d.target_psnr_db = r.settled_psnr_db;
  bool list_since_cut = false;
  for (const render::FrameRecord& f : frames) {
    if (f.time_s < cut_s || f.time_s >= segment_end_s) continue;
    list_since_cut = list_since_cut || f.list_fresh;
    if (list_since_cut && std::isfinite(f.mip_deficit) && f.mip_deficit <= kDetailDeficit) {
      d.deficit_s = f.time_s + frame_time_s - cut_s;  // frame f + 1 draws the residency f ended with
      break;
    }
  }
  return d;
}

double median_time_to_detail(const std::vector<TimeToDetail>& cuts) {
  if (cuts.empty()) return kNaN;
  std::vector<double> t;
  for (const TimeToDetail& d : cuts) t.push_back(std::isnan(d.deficit_s) ? kInf : d.deficit_s);
  std::sort(t.begin(), t.end());
  const size_t n = t.size();
  return n % 2 ? t[n / 2] : 0.5 * (t[n / 2 - 1] + t[n / 2]);  // +∞ when the middle holds a "never"
}

double headline_ratio(double a, double b) {
  if (std::isnan(a) || std::isnan(b) || (std::isinf(a) && std::isinf(b))) return kNaN;
  if (std::isinf(a)) return kInf;
  if (std::isinf(b)) return 0.0;
  if (b == 0) return a == 0 ? 1.0 : kInf;
  return a / b;
}

double nearest_rank(std::vector<double> values, double q) {
  if (values.empty()) return kNaN;
  std::sort(values.begin(), values.end());
  const size_t rank = static_cast<size_t>(std::ceil(q * static_cast<double>(values.size())));
  return values[std::min(values.size(), std::max<size_t>(rank, 1)) - 1];
}

std::vector<double> cut_times(const CameraPath& path) {
  std::vector<double> cuts;
  const auto& k = path.keys();
  for (size_t i = 1; i < k.size(); ++i) {
    const CameraPose& a = k[i - 1].pose;
    const CameraPose& b = k[i].pose;
    const bool moved = a.position[0] != b.position[0] || a.position[1] != b.position[1] ||
                       a.position[2] != b.position[2] || a.yaw_deg != b.yaw_deg || a.pitch_deg != b.pitch_deg;
    if (k[i].time_s == k[i - 1].time_s && moved) cuts.push_back(k[i].time_s);
  }
  return cuts;
}

CameraPath path_section(const CameraPath& path, double t0, double t1) {
  std::vector<CameraKey> keys;
  keys.push_back({0.0, path.sample(t0)});
  if (t1 > t0) {
    for (const CameraKey& k : path.keys())
      if (k.time_s > t0 && k.time_s < t1) keys.push_back({k.time_s - t0, k.pose});
    keys.push_back({t1 - t0, path.sample(t1)});
  }
  return CameraPath(std::move(keys));
}

RunAnalysis analyse_run(const std::vector<render::FrameRecord>& frames, double frame_time_s,
                        const std::vector<double>& cuts_s) {
  RunAnalysis a;
  a.frames = frames.size();
  std::vector<double> lat, tw, s, b, pages, hit, mse, psnr, ssim, deficit;
  // The frames the latency statistics count: all but the start-up frame, unless that is all there is.
  const auto counted = [&](const render::FrameRecord& f) {
    return f.index >= kWarmUpFrames || frames.size() <= kWarmUpFrames;
  };
  const auto add = [](LatencyParts& p, const render::FrameRecord& f) {
    ++p.frames;
    p.latency += f.latency_ms;
    p.plan += f.plan_ms;
    p.intake += f.intake_ms;
    p.bind += f.bind_ms;
    p.record += f.record_ms;
    p.gpu += f.gpu_ms;
    p.cycle += f.cycle_ms;
    p.mips += static_cast<double>(f.mips);
  };
  for (const render::FrameRecord& f : frames) {
    if (counted(f)) {
      lat.push_back(f.latency_ms);
      tw.push_back(f.tw_ms);
      add(a.all, f);
    }
    s.push_back(f.load_size_mb);
    b.push_back(f.mip_bias);
    pages.push_back(static_cast<double>(f.bound_pages));
    hit.push_back(f.server_hit_rate);
    mse.push_back(f.mse);
    psnr.push_back(f.psnr_db);
    ssim.push_back(f.ssim);
    if (std::isfinite(f.mse)) a.integrated_mse += f.mse * frame_time_s;
    if (std::isfinite(f.ssim)) a.integrated_dssim += (1.0 - f.ssim) * frame_time_s;
    deficit.push_back(f.mip_deficit);
    if (std::isfinite(f.mip_deficit)) a.integrated_mip_deficit += f.mip_deficit * frame_time_s;
    if (std::isfinite(f.popin_mse)) {
      ++a.popin_frames;
      a.max_popin_mse = std::max(a.max_popin_mse, f.popin_mse);
    }
  }
  a.latency_ms = stat3(lat);
  a.tw_ms = stat3(tw);
  a.load_size_mb = stat3(s);
  a.mip_bias = stat3(b);
  a.bound_pages = stat3(pages);
  a.server_hit_rate = stat3(hit);
  a.mse = stat3(mse);
  a.psnr_db = stat3(psnr);
  a.ssim = stat3(ssim);
  a.mip_deficit = stat3(deficit);
  const Rates r = windowed_rates(frames);
  a.mips_per_s = stat3(r.mips_per_s);
  a.mb_per_s = stat3(r.mb_per_s);
  if (!lat.empty()) {
    a.p95_latency_ms = nearest_rank(lat, 0.95);
    a.p99_latency_ms = nearest_rank(lat, 0.99);
    for (const render::FrameRecord& f : frames) {
      if (counted(f) && f.latency_ms >= a.p99_latency_ms) add(a.slowest, f);
    }
    for (LatencyParts* p : {&a.all, &a.slowest}) {
      const double n = static_cast<double>(std::max<uint64_t>(p->frames, 1));
      for (double* v : {&p->latency, &p->plan, &p->intake, &p->bind, &p->record, &p->gpu, &p->cycle, &p->mips}) *v /= n;
    }
  }
  const double end_s = frames.empty() ? 0.0 : frames.back().time_s + frame_time_s;
  for (size_t i = 0; i < cuts_s.size(); ++i) {
    if (cuts_s[i] >= end_s) break;
    const double next = i + 1 < cuts_s.size() ? std::min(cuts_s[i + 1], end_s) : end_s;
    a.recoveries.push_back(recovery_after_cut(frames, cuts_s[i], next));
    a.detail.push_back(time_to_detail(frames, cuts_s[i], next, frame_time_s));
  }
  return a;
}

std::string lockstep_difference(const std::vector<render::FrameRecord>& a, const std::vector<render::FrameRecord>& b) {
  if (a.size() != b.size()) return std::to_string(a.size()) + " frames against " + std::to_string(b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    const render::FrameRecord& x = a[i];
    const render::FrameRecord& y = b[i];
    auto at = [&](const char* what) { return "frame " + std::to_string(x.index) + ": " + what; };
    if (x.mips != y.mips) return at("mips");
    if (x.bytes != y.bytes) return at("bytes");
    if (x.bound_pages != y.bound_pages) return at("bound_pages");
    if (x.in_flight != y.in_flight) return at("in_flight");
    if (x.camera_still != y.camera_still) return at("camera_still");
    if (!same(x.time_s, y.time_s)) return at("time_s");
    if (!same(x.load_size_mb, y.load_size_mb)) return at("load_size_mb");
    if (!same(x.mip_bias, y.mip_bias)) return at("mip_bias");
    if (!same(x.mse, y.mse)) return at("mse");
    if (!same(x.psnr_db, y.psnr_db)) return at("psnr_db");
    if (!same(x.ssim, y.ssim)) return at("ssim");
    if (!same(x.popin_mse, y.popin_mse)) return at("popin_mse");
    if (x.list_fresh != y.list_fresh) return at("list_fresh");
    if (!same(x.mip_deficit, y.mip_deficit)) return at("mip_deficit");
    if (x.wasted_bytes != y.wasted_bytes) return at("wasted_bytes");
  }
  return "";
}

}  // namespace texstream::bench
