#include "texstream/render/measure/run_record.hpp"

#include <algorithm>
#include <limits>

namespace texstream::render {

Status RunRecord::compare_with(const std::filesystem::path& reference_dir, const std::filesystem::path& output_dir,
                               uint32_t width, uint32_t height) {
  auto measure = FrameMeasurement::open(reference_dir, output_dir, width, height);
  if (!measure) return measure.error();
  measure_ = std::move(*measure);
  return ok_status();
}

void RunRecord::start(const FrameCounters& totals, Clock::time_point now) {
  start_ = now;
  prev_ = totals;
}

Result<FrameRecord*> RunRecord::add(uint64_t index, double time_s, const CameraPose& pose, double latency_ms,
                                    double waited_ms, const FrameCounters& totals, const ControllerReadout& controller,
                                    const StreamQuality& quality, std::span<const std::byte> pixels) {
  const auto now = Clock::now();
  latencies_ms_.push_back(latency_ms);
  sum_load_mb_ += controller.load_size_mb;
  sum_bias_ += controller.mip_bias;
  sum_tw_ms_ += controller.tw_ms;
  FrameRecord f;
  f.index = index;
  f.time_s = time_s;
  f.wall_s = std::chrono::duration<double>(now - start_ - excluded_).count();
  f.latency_ms = latency_ms;
  f.waited_ms = waited_ms;
  f.tw_ms = controller.tw_ms;
  f.load_size_mb = controller.load_size_mb;
  f.mip_bias = controller.mip_bias;
  f.pace_mips = controller.pace_mips;
  f.mips = totals.mips_uploaded - prev_.mips_uploaded;
  f.bytes = totals.bytes_uploaded - prev_.bytes_uploaded;
  f.bound_pages = totals.bound_pages;
  // A restarted server counts from zero again.
  const uint64_t hits = totals.server_hits - std::min(prev_.server_hits, totals.server_hits);
  const uint64_t misses = totals.server_misses - std::min(prev_.server_misses, totals.server_misses);
  f.server_hit_rate = hits + misses ? static_cast<double>(hits) / static_cast<double>(hits + misses)
                                    : std::numeric_limits<double>::quiet_NaN();
  prev_ = totals;
  f.in_flight = totals.in_flight;
  f.wasted_bytes = totals.wasted_bytes;
  f.list_fresh = quality.list_fresh;
  f.mip_deficit = quality.mip_deficit;
  f.camera_still = prev_pose_ && same_pose(*prev_pose_, pose);
  prev_pose_ = pose;
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  f.mse = f.psnr_db = f.ssim = f.popin_mse = f.latency_off_ms = kNaN;
  if (measure_) TS_TRY(measure_->add(pixels));
  frames_.push_back(f);
  return &frames_.back();
}

void RunRecord::summarise(RunSummary& s) const {
  s.frames = frames_.size();
  s.frame_latency = LatencyStats::from(latencies_ms_);
  const double n = frames_.empty() ? 1.0 : static_cast<double>(frames_.size());
  s.avg_load_size_mb = sum_load_mb_ / n;
  s.avg_mip_bias = sum_bias_ / n;
  s.avg_weighted_latency_ms = sum_tw_ms_ / n;
  s.load_time_limited_frames = load_time_limited_frames_;
}

Status RunRecord::finish(const std::filesystem::path& output_dir) {
  if (measure_) {
    TS_TRY(measure_->measure(frames_));
    measure_.reset();  // removes the spill file
  }
  return write_frame_log(output_dir / "frames.csv", frames_);
}

}  // namespace texstream::render
