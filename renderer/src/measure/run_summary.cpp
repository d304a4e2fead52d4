#include "texstream/render/measure/run_summary.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numeric>

namespace texstream::render {

LatencyStats LatencyStats::from(std::vector<double> samples_ms) {
  LatencyStats s;
  if (samples_ms.empty()) return s;
  std::sort(samples_ms.begin(), samples_ms.end());
  const size_t n = samples_ms.size();
  s.median_ms = n % 2 ? samples_ms[n / 2] : 0.5 * (samples_ms[n / 2 - 1] + samples_ms[n / 2]);
  s.avg_ms = std::accumulate(samples_ms.begin(), samples_ms.end(), 0.0) / static_cast<double>(n);
  s.max_ms = samples_ms.back();
  return s;
}

std::string RunSummary::to_json() const {
  nlohmann::json j;
  j["device"] = device;
  j["output_dir"] = output_dir.string();
  j["frames"] = frames;
  j["frame_latency_ms"] = {
      {"median", frame_latency.median_ms}, {"avg", frame_latency.avg_ms}, {"max", frame_latency.max_ms}};
  j["mips_streamed"] = mips_streamed;
  j["mb_streamed"] = mb_streamed;
  j["server_ram_cache_hit_rate"] = server_ram_hit_rate;
  j["protocol_errors"] = protocol_errors;
  if (!stream_json.empty()) j["stream"] = nlohmann::json::parse(stream_json, nullptr, false);
  j["server_restarts"] = server_restarts;
  j["validation_errors"] = validation_errors;
  j["validation_warnings"] = validation_warnings;
  j["textures_resident"] = textures_resident;
  j["texture_count"] = texture_count;
  j["streaming_cycles"] = streaming_cycles;
  j["evictions"] = evictions;
  for (const auto& [key, tally] :
       {std::pair{"textures_refused", &textures_refused}, std::pair{"textures_charged", &textures_charged},
        std::pair{"textures_quarantined", &textures_quarantined}})
    j[key] = {{"count", tally->count}, {"first", tally->first}};
  j["wasted_bytes"] = wasted_bytes;
  // JSON has no NaN: nothing uploaded is null.
  j["wasted_bytes_frac"] = std::isfinite(wasted_bytes_frac) ? nlohmann::json(wasted_bytes_frac) : nlohmann::json();
  j["controller"] = {{"mode", controller_mode},
                     {"avg_load_size_mb", avg_load_size_mb},
                     {"avg_mip_bias", avg_mip_bias},
                     {"avg_weighted_latency_ms", avg_weighted_latency_ms},
                     {"load_time_limited_frames", load_time_limited_frames},
                     {"rejected_frames", controller_rejected_frames}};
  if (ground.has_ground) {
    j["ground_pages"] = {{"requested", ground.pages_requested},
                         {"uploaded", ground.pages_uploaded},
                         {"failed", ground.pages_failed},
                         {"cancelled", ground.pages_cancelled},
                         {"refused", ground.pages_refused},
                         {"evictions", ground.evictions},
                         {"frames", ground.frames},
                         {"frames_used", ground.frames_used},
                         {"needs_last_frame", ground.needs_last_frame}};
  }
  nlohmann::json startup = nlohmann::json::object();
  for (const auto& [stage, seconds] : startup_seconds) startup[stage] = seconds;
  j["startup_seconds"] = startup;
  return j.dump(2);
}

TextureTally TextureTally::of(const std::vector<uint32_t>& ids) {
  TextureTally t;
  t.count = ids.size();
  t.first.assign(ids.begin(), ids.begin() + static_cast<std::ptrdiff_t>(std::min(ids.size(), kFirst)));
  return t;
}

namespace {
// " (textures 3, 17, ...)" or nothing.
std::string ids_text(const TextureTally& t) {
  if (t.count == 0) return "";
  std::string s = " (texture";
  s += t.count > 1 ? "s " : " ";
  for (size_t i = 0; i < t.first.size(); ++i) s += (i ? ", " : "") + std::to_string(t.first[i]);
  if (t.count > t.first.size()) s += ", ...";
  return s + ")";
}
}  // namespace

std::string RunSummary::to_text() const {
  return fmt::format(
      "texstream-render summary\n"
      "  device              {}\n"
      "  frames              {}\n"
      "  frame latency       median {:.2f} ms, avg {:.2f} ms, max {:.2f} ms\n"
      "  streamed            {} mips, {:.2f} MB in {} cycles ({:.1f} % never displayed)\n"
      "  server RAM hit rate {:.1f} %\n"
      "  protocol errors     {}\n"
      "  server restarts     {}\n"
      "  validation          {} errors, {} warnings\n"
      "  textures resident   {} of {} ({} evictions)\n"
      "  textures given up   {} refused{}, {} charged with a server death{}, {} quarantined{}\n"
      "  controller          {}: avg s {:.3f} MB, avg b {:.2f}, avg t_w {:.2f} ms, {} load-time-limited frames\n"
      "{}"
      "  output              {}\n",
      device, frames, frame_latency.median_ms, frame_latency.avg_ms, frame_latency.max_ms, mips_streamed, mb_streamed,
      streaming_cycles, 100.0 * wasted_bytes_frac, 100.0 * server_ram_hit_rate, protocol_errors, server_restarts,
      validation_errors, validation_warnings, textures_resident, texture_count, evictions, textures_refused.count,
      ids_text(textures_refused), textures_charged.count, ids_text(textures_charged), textures_quarantined.count,
      ids_text(textures_quarantined), controller_mode, avg_load_size_mb, avg_mip_bias, avg_weighted_latency_ms,
      load_time_limited_frames,
      ground.has_ground
          ? fmt::format(
                "  ground pages        {} uploaded of {} requested ({} failed, {} superseded), {} of {} frames used, "
                "{} evictions\n",
                ground.pages_uploaded, ground.pages_requested, ground.pages_failed, ground.pages_cancelled,
                ground.frames_used, ground.frames, ground.evictions)
          : std::string(),
      output_dir.string());
}

Status RunSummary::write_json(const std::filesystem::path& file) const {
  std::ofstream out(file);
  out << to_json() << "\n";
  out.close();
  if (!out) return make_error(ErrorCode::kIo, file.string() + ": write failed");
  return ok_status();
}

}  // namespace texstream::render
