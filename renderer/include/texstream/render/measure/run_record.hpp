#pragma once
// The record of one texstream-render run as it goes: one FrameRecord per frame (frames.csv, frame_log.hpp),
// the frames' latencies and the controller's per-frame outputs for the summary, and, with
// render.reference_dir, every frame's pixels for the image error measured after the last frame
// (frame_measurement.hpp). The frame loop hands it plain numbers (FrameCounters), so nothing here knows the
// cache, the stream client or the device.
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "texstream/common/camera_path.hpp"
#include "texstream/common/result.hpp"
#include "texstream/render/measure/frame_log.hpp"
#include "texstream/render/measure/frame_measurement.hpp"
#include "texstream/render/measure/run_summary.hpp"

namespace texstream::render {

// Running totals and levels as a frame ends; the record turns the totals into the frame's share.
struct FrameCounters {
  uint64_t mips_uploaded = 0;   // texture cache: mips published, all frames
  uint64_t bytes_uploaded = 0;  // and their bytes
  uint64_t bound_pages = 0;     // sparse pages bound now
  uint64_t server_hits = 0;     // server RAM cache hits and misses, all frames
  uint64_t server_misses = 0;
  uint64_t in_flight = 0;     // requests outstanding now
  uint64_t wasted_bytes = 0;  // mips that left the cache never displayed, all frames (written as is)
};

// What the view got of its mips as the frame ends (frame_log.hpp, docs/design/stream_metrics.md).
struct StreamQuality {
  bool list_fresh = false;  // this frame read the visibility list back
  double mip_deficit = 0;   // weighted mip deficit of the latest list (NaN: no list read yet)
};

// The adaptive controller's outputs after the frame (seed 000 §3.4): for the next cycle.
struct ControllerReadout {
  double tw_ms = 0;         // t_w (Eq. 5)
  double load_size_mb = 0;  // s, 10^6 bytes
  double mip_bias = 0;      // b, levels
  double pace_mips = 0;     // the most mips the next frame takes in (NaN: no pace)
};

class RunRecord {
 public:
  using Clock = std::chrono::steady_clock;

  // render.reference_dir: every frame's pixels (width x height RGBA8) are kept for measure at finish().
  Status compare_with(const std::filesystem::path& reference_dir, const std::filesystem::path& output_dir,
                      uint32_t width, uint32_t height);
  bool compares() const { return measure_ != nullptr; }

  // Frame 0 starts at `now`; the frames' shares count from `totals` (a preload is not frame 0's streaming).
  void start(const FrameCounters& totals, Clock::time_point now);
  // Time that is not the run's (measurement, PNG writing): left out of every later frame's wall_s.
  void exclude(Clock::duration d) { excluded_ += d; }
  // A frame whose completion intake hit controller.load_time_ms.
  void count_load_time_limited() { ++load_time_limited_frames_; }

  // Adds frame `index` at virtual time `time_s`, seen from `pose`: its latency and lock-step wait, its
  // share of `totals`, the controller's outputs, the stream quality, and (compares()) its pixels. Returns its
  // record, for the fields only some runs have (latency_off_ms).
  Result<FrameRecord*> add(uint64_t index, double time_s, const CameraPose& pose, double latency_ms, double waited_ms,
                           const FrameCounters& totals, const ControllerReadout& controller,
                           const StreamQuality& quality, std::span<const std::byte> pixels = {});

  // The latency of the last frame added (0 before the first).
  double last_latency_ms() const { return latencies_ms_.empty() ? 0.0 : latencies_ms_.back(); }
  uint64_t frames() const { return frames_.size(); }

  // The summary's per-frame part: frames, frame latency, the controller's averages, the load-time-limited
  // frames.
  void summarise(RunSummary& s) const;
  // Measures the image error (compares()) and writes <output_dir>/frames.csv.
  Status finish(const std::filesystem::path& output_dir);

 private:
  std::vector<FrameRecord> frames_;
  std::vector<double> latencies_ms_;
  double sum_load_mb_ = 0, sum_bias_ = 0, sum_tw_ms_ = 0;
  uint64_t load_time_limited_frames_ = 0;
  Clock::time_point start_{};
  Clock::duration excluded_{0};
  FrameCounters prev_;
  std::optional<CameraPose> prev_pose_;
  std::unique_ptr<FrameMeasurement> measure_;
};

}  // namespace texstream::render
