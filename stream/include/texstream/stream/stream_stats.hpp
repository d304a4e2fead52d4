#pragma once
// What StreamClient counts and how it prints it: StreamStats, the IPC time per frame, and one list of their
// fields (kStreamCounters, kIpcFields) from which the `key value` text ($TEXSTREAM_STREAM_STATS), the "stream"
// object of summary.json and texstream-chaos's reading of the text are all made.
#include <array>
#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "texstream/common/latency_histogram.hpp"
#include "texstream/common/result.hpp"
#include "texstream/protocol/records.hpp"

namespace texstream::stream {

enum class StreamServerState : uint8_t {
  kExternal,  // spawn_server = false: someone else serves the segment
  kRunning,
  kBackingOff,
  kColormapOnly,
  kBroken,  // external server broke a ring: nothing is sent until reset_external_server()
};
const char* to_string(StreamServerState state);

// Time the renderer's frame thread spends inside the client (poll, try_request, begin_cycle, restarts),
// without the time spent in the MipSink's callbacks (the renderer's own work). One sample per "frame": from
// one poll() to the next, so requests sent after a poll count with it. Issue 9 bounds it: no frame may be
// blocked by IPC for more than 1 ms (p99.99). The project's one histogram (common/latency_histogram.hpp) in
// 10 µs units with 2048 exact buckets (up to 20.48 ms: the old linear 10 µs buckets); the maximum is exact.
class IpcTimeHistogram {
 public:
  static constexpr uint64_t kBucketNs = 10'000;
  void add(uint64_t ns) { h_.record_one_writer(ns); }  // the frame thread only
  uint64_t samples() const { return h_.count(); }
  uint64_t max_ns() const { return h_.max(); }
  double total_ms() const { return static_cast<double>(h_.sum()) / 1e6; }
  // Upper edge of the bucket holding quantile q (0..1), in µs; the exact maximum above the last bucket.
  double quantile_us(double q) const;
  uint64_t above(uint64_t ns) const { return h_.count_above(ns); }  // samples longer than ns (bucket resolution)

 private:
  LogLinearHistogram<11, 11, kBucketNs> h_;
};

struct StreamStats {
  uint64_t requests_sent = 0;
  uint64_t releases_sent = 0;
  uint64_t completions_ok = 0;                                 // committed to the sink (checksum matched)
  uint64_t completions_rejected = 0;                           // kOk whose payload the checks refused
  uint64_t payload_checksum_failures = 0;                      // of those: copied, checksum did not match
  uint64_t completions_failed[kMaxCompletionStatus + 1] = {};  // by CompletionStatus value
  uint64_t requests_lost = 0;                                  // in flight when the server died
  uint64_t requests_timed_out = 0;                             // unanswered for StreamClientOptions::request_timeout
  uint64_t bytes_received = 0;                                 // payload bytes committed (mips)
  // Pages of page files (kLoadPage; not in the mip counters above, except protocol_errors and
  // completions_rejected, which count every refused record).
  uint64_t pages_requested = 0;
  uint64_t pages_ok = 0;      // committed to the page sink (checks and checksum passed)
  uint64_t pages_failed = 0;  // ended without a payload: the server's status, refused, lost or timed out
  uint64_t protocol_errors = 0;
  uint64_t server_restarts = 0;  // spawns after the first
  uint64_t server_deaths = 0;
  uint64_t server_crashes = 0;  // deaths counted as crashes (RestartPolicy)
  // Servers in a row (up to now) that died before attaching to the segment: a binary that cannot start (a
  // bad option, a missing library) rather than one that crashed while serving. 0 once one attached.
  uint64_t server_deaths_before_attach = 0;
  // Of those, the ones in a row that exited with kServerExitBadConfig: the server refused its arguments,
  // configuration or scene, which no restart changes. 0 once one attached or died any other way.
  uint64_t server_refusals_before_attach = 0;
  // server.spawn = false: the pid of a standalone server that refused the segment because it reads another
  // scene (ServerBlock::refused_by); 0 if none. No restart of ours changes that: the run ends (renderer_app).
  uint32_t standalone_refused_by = 0;
  uint64_t crash_signal_deaths = 0;   // deaths by a crash signal the server raised itself
  uint64_t textures_quarantined = 0;  // loaded during kQuarantineAfterCrashes such deaths
  // Recovery (issue 9): a request in flight when the server died, sent again to a later server, must be
  // answered (any status) within kRecoveryDeadline of being sent again.
  uint64_t lost_resent = 0;  // lost requests sent again
  uint64_t lost_answered_in_time = 0;
  uint64_t unserved_after_restart = 0;  // answered late, or still unanswered past the deadline
  uint64_t in_flight = 0;
  uint64_t slots_held = 0;       // handed to us, not yet handed back
  uint64_t releases_queued = 0;  // waiting for room in the request ring
  // Copied from ServerBlock, summed over every server this client has run.
  uint64_t server_ram_cache_hits = 0;
  uint64_t server_ram_cache_misses = 0;
  uint64_t server_bytes_read = 0;
  uint64_t server_requests_cancelled = 0;
  uint64_t server_syscalls = 0;  // the server's dispatcher and workers (ServerBlock::syscalls)
  // This process's kernel crossings made by our code (syscall_count.hpp): per frame with ipc_frames.
  uint64_t syscalls = 0;
  StreamServerState server_state = StreamServerState::kExternal;
};

// The IPC time per frame as printed: frames, total and quantiles (IpcTimeHistogram's figures).
struct IpcSummary {
  double frames = 0;
  double total_ms = 0;
  double p50_us = 0;
  double p99_us = 0;
  double p999_us = 0;
  double p9999_us = 0;
  double max_us = 0;
  double frames_over_1ms = 0;
  static IpcSummary of(const IpcTimeHistogram& h);
};

// The one list of the counters that are printed, by name. completions_failed (a sum over the statuses) and
// server_state (a name) are the two lines not in it; a new counter is one line here.
struct StreamCounterField {
  std::string_view name;
  uint64_t StreamStats::*member;
};
inline constexpr std::array<StreamCounterField, 31> kStreamCounters{{
    {"requests_sent", &StreamStats::requests_sent},
    {"releases_sent", &StreamStats::releases_sent},
    {"completions_ok", &StreamStats::completions_ok},
    {"completions_rejected", &StreamStats::completions_rejected},
    {"payload_checksum_failures", &StreamStats::payload_checksum_failures},
    {"requests_lost", &StreamStats::requests_lost},
    {"requests_timed_out", &StreamStats::requests_timed_out},
    {"bytes_received", &StreamStats::bytes_received},
    {"pages_requested", &StreamStats::pages_requested},
    {"pages_ok", &StreamStats::pages_ok},
    {"pages_failed", &StreamStats::pages_failed},
    {"protocol_errors", &StreamStats::protocol_errors},
    {"server_restarts", &StreamStats::server_restarts},
    {"server_deaths", &StreamStats::server_deaths},
    {"server_crashes", &StreamStats::server_crashes},
    {"server_deaths_before_attach", &StreamStats::server_deaths_before_attach},
    {"server_refusals_before_attach", &StreamStats::server_refusals_before_attach},
    {"crash_signal_deaths", &StreamStats::crash_signal_deaths},
    {"textures_quarantined", &StreamStats::textures_quarantined},
    {"lost_resent", &StreamStats::lost_resent},
    {"lost_answered_in_time", &StreamStats::lost_answered_in_time},
    {"unserved_after_restart", &StreamStats::unserved_after_restart},
    {"in_flight", &StreamStats::in_flight},
    {"slots_held", &StreamStats::slots_held},
    {"releases_queued", &StreamStats::releases_queued},
    {"server_ram_cache_hits", &StreamStats::server_ram_cache_hits},
    {"server_ram_cache_misses", &StreamStats::server_ram_cache_misses},
    {"server_bytes_read", &StreamStats::server_bytes_read},
    {"server_requests_cancelled", &StreamStats::server_requests_cancelled},
    {"server_syscalls", &StreamStats::server_syscalls},
    {"syscalls", &StreamStats::syscalls},
}};
struct IpcField {
  std::string_view name;
  double IpcSummary::*member;
};
inline constexpr std::array<IpcField, 8> kIpcFields{{
    {"ipc_frames", &IpcSummary::frames},
    {"ipc_total_ms", &IpcSummary::total_ms},
    {"ipc_p50_us", &IpcSummary::p50_us},
    {"ipc_p99_us", &IpcSummary::p99_us},
    {"ipc_p999_us", &IpcSummary::p999_us},
    {"ipc_p9999_us", &IpcSummary::p9999_us},
    {"ipc_max_us", &IpcSummary::max_us},
    {"ipc_frames_over_1ms", &IpcSummary::frames_over_1ms},
}};

// `key value` lines: every field of the lists above, completions_failed and server_state.
std::string format_stream_stats(const StreamStats& s, const IpcTimeHistogram& ipc_time);
// The same fields as one JSON object (summary.json's "stream").
nlohmann::json stream_stats_json(const StreamStats& s, const IpcTimeHistogram& ipc_time);

// format_stream_stats's text read back (texstream-chaos): the fields by the same lists. A line whose key is not
// in them, or whose value is not a number where one belongs, is an error naming `source` and the line.
struct StreamStatsText {
  StreamStats stats;  // completions_failed[0] holds the printed sum
  IpcSummary ipc;
  std::string server_state;
};
Result<StreamStatsText> parse_stream_stats(std::string_view text, const std::string& source);

}  // namespace texstream::stream
