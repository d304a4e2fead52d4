#pragma once
// What a run of texstream-render reports at its end: printed, and written as <output_dir>/summary.json.
#include <cstdint>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "texstream/common/result.hpp"

namespace texstream::render {

struct LatencyStats {
  double median_ms = 0;
  double avg_ms = 0;
  double max_ms = 0;
  static LatencyStats from(std::vector<double> samples_ms);
};

// Textures a run gave up on, by kind: how many, and the first few ids (ascending or in the order met).
struct TextureTally {
  uint64_t count = 0;
  std::vector<uint32_t> first;  // at most kFirst
  static constexpr size_t kFirst = 5;
  static TextureTally of(const std::vector<uint32_t>& ids);
};

struct RunSummary {
  std::string device;
  std::filesystem::path output_dir;
  uint64_t frames = 0;
  LatencyStats frame_latency;
  uint64_t mips_streamed = 0;      // uploaded into the cache and published
  double mb_streamed = 0;          // 10^6 bytes of those
  double server_ram_hit_rate = 0;  // server RAM cache hits / (hits + misses); 0 when nothing was asked
  uint64_t protocol_errors = 0;
  std::string stream_json;  // the stream client's counters as a JSON object (stream_stats_json); empty: none
  uint64_t server_restarts = 0;
  uint64_t validation_errors = 0;
  uint64_t validation_warnings = 0;
  uint64_t textures_resident = 0;  // textures with at least one mip in the cache at the end
  uint64_t texture_count = 0;
  uint64_t streaming_cycles = 0;
  uint64_t evictions = 0;
  TextureTally textures_refused;      // the cache cannot hold them (another texel format, larger than a layer)
  TextureTally textures_charged;      // loading while a server crashed or hung (crash_quarantine.hpp)
  TextureTally textures_quarantined;  // charged kQuarantineAfterCrashes times: never asked again this run
  // Streamed mips never displayed while resident (MipUseLedger, docs/design/stream_metrics.md): their bytes,
  // and those ÷ every byte uploaded (render.preload_all included; NaN when nothing was uploaded).
  uint64_t wasted_bytes = 0;
  double wasted_bytes_frac = 0;
  // Adaptive controller (seed 000 §3.4): per-frame averages of its outputs and of t_w.
  std::string controller_mode;
  double avg_load_size_mb = 0;              // s, 10^6 bytes
  double avg_mip_bias = 0;                  // b, levels
  double avg_weighted_latency_ms = 0;       // t_w (Eq. 5)
  uint64_t load_time_limited_frames = 0;    // frames whose completion intake hit controller.load_time_ms
  uint64_t controller_rejected_frames = 0;  // frame latencies the controller refused (non-finite, negative)
  // The ground's pages (scene.json "ground", issue 28); has_ground false: none drawn.
  struct Ground {
    bool has_ground = false;
    uint64_t pages_requested = 0, pages_uploaded = 0, pages_failed = 0, pages_cancelled = 0, pages_refused = 0;
    uint64_t evictions = 0;
    uint64_t frames = 0, frames_used = 0;  // page frames of the cache, and those holding a page at the end
    uint64_t needs_last_frame = 0;         // needbuffer texels that saw the ground in the last frame
  } ground;
  // Start-up, stage by stage in order (seconds of wall time): what grows with the scene's size.
  std::vector<std::pair<std::string, double>> startup_seconds;

  std::string to_json() const;
  std::string to_text() const;
  Status write_json(const std::filesystem::path& file) const;
};

}  // namespace texstream::render
