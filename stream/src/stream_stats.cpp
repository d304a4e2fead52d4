#include "texstream/stream/stream_stats.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace texstream::stream {

const char* to_string(StreamServerState state) {
  switch (state) {
    case StreamServerState::kExternal:
      return "external";
    case StreamServerState::kRunning:
      return "running";
    case StreamServerState::kBackingOff:
      return "backing off";
    case StreamServerState::kColormapOnly:
      return "colormap only";
    case StreamServerState::kBroken:
      return "broken";
  }
  return "?";
}

double IpcTimeHistogram::quantile_us(double q) const {
  const uint64_t samples = h_.count();
  if (samples == 0) return 0.0;
  const auto rank = static_cast<uint64_t>(std::ceil(std::clamp(q, 0.0, 1.0) * static_cast<double>(samples)));
  const uint32_t bucket = h_.bucket_at_rank(std::max<uint64_t>(rank, 1));
  const double max_us = static_cast<double>(h_.max()) / 1e3;
  // The last bucket holds everything from 20.47 ms up: there the exact maximum is the answer.
  if (bucket >= h_.kBuckets - 1) return max_us;
  return std::min(static_cast<double>((h_.bucket_upper(bucket) + 1) * kBucketNs) / 1e3, max_us);
}

std::string format_stream_stats(const StreamStats& s, const IpcTimeHistogram& ipc_time) {
  std::ostringstream o;
  o << "requests_sent " << s.requests_sent << "\n"
    << "releases_sent " << s.releases_sent << "\n"
    << "completions_ok " << s.completions_ok << "\n"
    << "completions_rejected " << s.completions_rejected << "\n"
    << "payload_checksum_failures " << s.payload_checksum_failures << "\n";
  uint64_t failed = 0;
  for (uint64_t f : s.completions_failed) failed += f;
  o << "completions_failed " << failed << "\n"
    << "requests_lost " << s.requests_lost << "\n"
    << "requests_timed_out " << s.requests_timed_out << "\n"
    << "bytes_received " << s.bytes_received << "\n"
    << "protocol_errors " << s.protocol_errors << "\n"
    << "server_restarts " << s.server_restarts << "\n"
    << "server_deaths " << s.server_deaths << "\n"
    << "server_crashes " << s.server_crashes << "\n"
    << "server_deaths_before_attach " << s.server_deaths_before_attach << "\n"
    << "server_refusals_before_attach " << s.server_refusals_before_attach << "\n"
    << "crash_signal_deaths " << s.crash_signal_deaths << "\n"
    << "textures_quarantined " << s.textures_quarantined << "\n"
    << "lost_resent " << s.lost_resent << "\n"
    << "lost_answered_in_time " << s.lost_answered_in_time << "\n"
    << "unserved_after_restart " << s.unserved_after_restart << "\n"
    << "in_flight " << s.in_flight << "\n"
    << "server_state " << to_string(s.server_state) << "\n"
    << "ipc_frames " << ipc_time.samples() << "\n"
    << "ipc_total_ms " << ipc_time.total_ms() << "\n"
    << "ipc_p50_us " << ipc_time.quantile_us(0.5) << "\n"
    << "ipc_p99_us " << ipc_time.quantile_us(0.99) << "\n"
    << "ipc_p999_us " << ipc_time.quantile_us(0.999) << "\n"
    << "ipc_p9999_us " << ipc_time.quantile_us(0.9999) << "\n"
    << "ipc_max_us " << static_cast<double>(ipc_time.max_ns()) / 1e3 << "\n"
    << "ipc_frames_over_1ms " << ipc_time.above(1'000'000) << "\n";
  return o.str();
}

}  // namespace texstream::stream
