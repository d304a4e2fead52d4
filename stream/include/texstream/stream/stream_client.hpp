#pragma once
// The renderer's end of the shared-memory protocol: it creates the segment, spawns and supervises
// texstream-server (ServerProcess), sends load requests, and receives, validates and hands over completed
// mips. No Vulkan: the renderer gives it a MipSink that says where a mip's bytes go (e.g. a mapped staging
// buffer) and what to do with them once checked.
//
// Once per frame, never blocking (DESIGN.md: nothing on the frame path waits on the server):
//   client.begin_cycle();                       // a streaming cycle starts: new Generation
//   states.run_cycle(list, s, b, client.sender(), max_mips_per_cycle);   // Algorithm 1 → kLoad requests
//   client.poll(sink, budget);                  // heartbeat, server liveness, completions → sink
//
// Trust: every completion is copied out of the ring once and validated (check_completion, then the
// texture table, then "did we ask for this", then slot ownership) before any slot byte is read; the
// payload is copied once and its checksum computed on the copy. A server that breaks the protocol loses
// only its own records; one that corrupts a ring position is killed and restarted.
//
// Slot ownership (segment_layout.hpp): the server owns every slot at start; a kOk completion hands its slot
// to us; a kReleaseSlot request hands it back. We track which slots we hold, so a completion naming a slot
// we already hold is refused (and never released twice).
//
// Crash quarantine (issue 9): the server records in ServerBlock::loading the texture each load worker is
// working on. When the server dies by a crash signal it raised itself (SIGSEGV, SIGBUS, SIGABRT, SIGFPE,
// SIGILL: never SIGKILL, which is the watchdog, texstream-chaos or the OOM killer), the textures in those
// words are charged one crash each, read before the segment is reset. A texture charged
// kQuarantineAfterCrashes times is quarantined for this client's life: it is never requested again (every
// request of it fails at once with kCorrupt, as a broken file does, so the texture states leave it on its
// colormap), and its requests lost with the dead server fail with kCorrupt instead of kCancelled. A
// texture that merely shared a crash with a guilty one is charged once and served on.
//
// Single-threaded: the renderer's frame thread makes every call.
#include <chrono>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"
#include "texstream/protocol/completion_check.hpp"
#include "texstream/common/ids.hpp"
#include "texstream/protocol/records.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/protocol/spsc_ring.hpp"
#include "texstream/stream/server_process.hpp"
#include "texstream/stream/texture_states.hpp"

namespace texstream {

// Where completed mips go. Implemented by the renderer; called only from within StreamClient::poll.
class MipSink {
 public:
  virtual ~MipSink() = default;
  // Room for `bytes` of (texture, mip), or an empty span for "no room now": the completion then stays
  // pending (its slot still ours) and is offered again first by the next poll. A non-empty span must hold
  // at least `bytes` bytes (a shorter one is a bug of the sink and aborts).
  virtual std::span<std::byte> reserve(TextureId texture, MipLevel mip, uint64_t bytes) = 0;
  // `data` (the first `bytes` of the reserved span) holds the mip, checksum verified.
  virtual void commit(TextureId texture, MipLevel mip, std::span<std::byte> data) = 0;
  // The answer for (texture, mip) was refused: a record that failed validation (then `reserved` is
  // empty), or a payload whose checksum did not match (then `reserved` is the span reserve() gave, free
  // again). Nothing is uploaded; the texture state machine counts it and asks again.
  virtual void reject(TextureId texture, MipLevel mip, std::span<std::byte> reserved) = 0;
  // The request ended without a payload: the server's status, or kCancelled for a request lost with a
  // dead or restarted server. The texture state machine decides whether to ask again.
  virtual void failed(TextureId texture, MipLevel mip, CompletionStatus status) = 0;
};

// Why a request was or was not sent.
enum class RequestOutcome : uint8_t {
  kSent,
  kAlreadyInFlight,   // that (texture, mip) is still in flight
  kInFlightLimit,     // stream.max_requests_in_flight reached
  kRingFull,          // no room in the request ring (room is kept for slot releases)
  kNoServer,          // the server is dead, backing off or in colormap-only mode
  kUnknownTexture,    // id outside the texture table
  kBadMip,            // mip level >= the texture's mip count
  kQuarantined,       // the texture was being loaded when the server crashed twice: failed (kCorrupt) at next poll
};
const char* to_string(RequestOutcome outcome);
// kSent and kQuarantined (answered kCorrupt at the next poll) → kSent; other outcomes about this one
// (texture, mip) → kSkip; outcomes about the whole pipe → kStop.
SendResult to_send_result(RequestOutcome outcome);

enum class StreamServerState : uint8_t {
  kExternal,      // spawn_server = false: someone else serves the segment
  kRunning,
  kBackingOff,
  kColormapOnly,
  kBroken,        // external server broke a ring: nothing is sent until reset_external_server()
};
const char* to_string(StreamServerState state);

// Time the renderer's frame thread spends inside the client (poll, try_request, begin_cycle, restarts),
// without the time spent in the MipSink's callbacks (the renderer's own work). One sample per "frame": from
// one poll() to the next, so requests sent after a poll count with it. Issue 9 bounds it: no frame may be
// blocked by IPC for more than 1 ms (p99.99). 10 µs buckets up to 20 ms; the maximum is kept exactly.
class IpcTimeHistogram {
 public:
  static constexpr uint64_t kBucketNs = 10'000;
  static constexpr size_t kBuckets = 2000;
  void add(uint64_t ns);
  uint64_t samples() const { return samples_; }
  uint64_t max_ns() const { return max_ns_; }
  double total_ms() const { return static_cast<double>(total_ns_) / 1e6; }
  // Upper edge of the bucket holding quantile q (0..1), in µs; the exact maximum above the last bucket.
  double quantile_us(double q) const;
  uint64_t above(uint64_t ns) const;  // samples longer than ns (bucket resolution)

 private:
  std::vector<uint64_t> buckets_ = std::vector<uint64_t>(kBuckets, 0);
  uint64_t overflow_ = 0, samples_ = 0, max_ns_ = 0, total_ns_ = 0;
};

struct StreamStats {
  uint64_t requests_sent = 0;
  uint64_t releases_sent = 0;
  uint64_t completions_ok = 0;                           // committed to the sink (checksum matched)
  uint64_t completions_rejected = 0;                     // kOk whose payload the checks refused
  uint64_t payload_checksum_failures = 0;                // of those: copied, checksum did not match
  uint64_t completions_failed[kMaxCompletionStatus + 1] = {};  // by CompletionStatus value
  uint64_t requests_lost = 0;                            // in flight when the server died
  uint64_t requests_timed_out = 0;                       // unanswered for StreamClientOptions::request_timeout
  uint64_t bytes_received = 0;                           // payload bytes committed
  uint64_t protocol_errors = 0;
  uint64_t server_restarts = 0;                          // spawns after the first
  uint64_t server_deaths = 0;
  uint64_t server_crashes = 0;                           // deaths counted as crashes (RestartPolicy)
  // Servers in a row (up to now) that died before attaching to the segment: a binary that cannot start (a
  // bad option, a missing library) rather than one that crashed while serving. 0 once one attached.
  uint64_t server_deaths_before_attach = 0;
  // Of those, the ones in a row that exited with kServerExitBadConfig: the server refused its arguments,
  // configuration or scene, which no restart changes. 0 once one attached or died any other way.
  uint64_t server_refusals_before_attach = 0;
  // server.spawn = false: the pid of a standalone server that refused the segment because it reads another
  // scene (ServerBlock::refused_by); 0 if none. No restart of ours changes that: the run ends (renderer_app).
  uint32_t standalone_refused_by = 0;
  uint64_t crash_signal_deaths = 0;                      // deaths by a crash signal the server raised itself
  uint64_t textures_quarantined = 0;                     // loaded during kQuarantineAfterCrashes such deaths
  // Recovery (issue 9): a request in flight when the server died, sent again to a later server, must be
  // answered (any status) within kRecoveryDeadline of being sent again.
  uint64_t lost_resent = 0;                              // lost requests sent again
  uint64_t lost_answered_in_time = 0;
  uint64_t unserved_after_restart = 0;                   // answered late, or still unanswered past the deadline
  uint64_t in_flight = 0;
  uint64_t slots_held = 0;                               // handed to us, not yet handed back
  uint64_t releases_queued = 0;                          // waiting for room in the request ring
  // Copied from ServerBlock, summed over every server this client has run.
  uint64_t server_ram_cache_hits = 0;
  uint64_t server_ram_cache_misses = 0;
  uint64_t server_bytes_read = 0;
  uint64_t server_requests_cancelled = 0;
  StreamServerState server_state = StreamServerState::kExternal;
};

struct StreamClientOptions {
  // false: do not spawn texstream-server. Whoever serves the segment opens it by name (Segment::open) —
  // tests play the server in a thread this way, and a renderer can attach to a server started by hand.
  // Without a child there is no restart: a ring error puts the client in kBroken until
  // reset_external_server().
  bool spawn_server = true;
  RestartPolicy restart;
  // Clock for back-off and the heartbeat watchdog (tests inject a virtual one). Default: steady_clock.
  std::function<SteadyTime()> clock;
  // A request unanswered this long is failed locally (kTimedOut) and its in-flight place freed, so a server
  // that keeps its heartbeat but drops or garbles answers cannot fill stream.max_requests_in_flight forever.
  // A late answer is then refused as unsolicited (its slot handed back). 10 s: far above a queue of 64
  // one-MiB misses at server.rate_limit_mb_s = 10. (A config key protocol.request_timeout_ms is proposed.)
  std::chrono::milliseconds request_timeout{10000};
};

class StreamClient {
 public:
  static constexpr std::chrono::milliseconds kRecoveryDeadline{2000};  // issue 9: served within 2 s of a restart
  // Crashes while a texture was being loaded before it is quarantined (issue 9: "a file that crashed it
  // twice"): one is forgiven, as a texture may share a crash with another one that caused it.
  static constexpr uint32_t kQuarantineAfterCrashes = 2;
  // Removes stale "texstream-" segments, creates this one (protocol.segment_name or "texstream-<pid>",
  // sized from `config.protocol`), and spawns the server (unless options.spawn_server is false) with
  // `--scene scene_dir`, `--config config_file` (if not empty) and each override as `--set`.
  // `shapes` is the scene's texture table, indexed by texture id.
  static Result<std::unique_ptr<StreamClient>> start(const Config& config, std::vector<TextureShape> shapes,
                                                     const std::filesystem::path& scene_dir,
                                                     const std::filesystem::path& config_file,
                                                     const std::vector<std::string>& overrides,
                                                     StreamClientOptions options = {});
  ~StreamClient();
  StreamClient(const StreamClient&) = delete;
  StreamClient& operator=(const StreamClient&) = delete;

  // A new streaming cycle: a new Generation, published in RendererBlock.generation (a newer generation
  // lets the server drop requests of older ones it has not started).
  void begin_cycle();
  Generation generation() const { return generation_; }

  // Pushes a kLoad for (texture, mip) with the current generation. Never blocks.
  RequestOutcome try_request(TextureId texture, MipLevel mip, float priority);
  bool request(TextureId texture, MipLevel mip, float priority) {
    return try_request(texture, mip, priority) == RequestOutcome::kSent;
  }
  // A Sender for TextureStates::run_cycle that sends through try_request.
  TextureStates::Sender sender();

  // Once per frame: bumps RendererBlock.heartbeat, pushes queued slot releases, supervises the server
  // (reap, watchdog, restart), then takes completions off the ring and hands at most `max_mips` payloads
  // to `sink` (statuses without payload are not counted against it).
  void poll(MipSink& sink, size_t max_mips);

  StreamStats stats() const;
  const IpcTimeHistogram& ipc_time() const { return ipc_time_; }
  // `key value` lines: every StreamStats counter and the IPC-time quantiles. Written by the destructor to
  // $TEXSTREAM_STREAM_STATS when that is set (texstream-chaos reads it; the renderer's summary.json is
  // written elsewhere).
  std::string stats_text() const;
  bool in_flight(TextureId texture, MipLevel mip) const;
  // stats()'s standalone_refused_by and server_refusals_before_attach without building the whole StreamStats
  // (the renderer asks every frame; stats() counts held slots and scans the lost requests).
  uint32_t standalone_refused_by() const { return stats_.standalone_refused_by; }
  uint64_t server_refusals_before_attach() const { return stats_.server_refusals_before_attach; }
  // Empty if a server is attached to the segment now; else why not, for an error that has to say it.
  std::string unattached_reason() const;
  bool quarantined(TextureId texture) const { return quarantined_.count(texture.value) != 0; }
  const Segment& segment() const { return *segment_; }
  Segment& segment() { return *segment_; }
  int server_pid() const { return process_ ? process_->pid() : -1; }
  // How the last spawned server ended ("pid 12 exited with status 2"); empty if none has.
  const std::string& last_server_exit() const { return last_server_exit_; }

  // Kills the spawned server as if it had hung (tests of the restart path; a renderer's "restart server"
  // key). With spawn_server = false: marks everything in flight lost and resets the segment's rings — the
  // caller guarantees the external server has let go of the segment.
  void restart_server(const std::string& why, MipSink& sink);
  void reset_external_server(MipSink& sink) { restart_server("reset requested", sink); }

 private:
  struct InFlight {
    Generation generation;
    SteadyTime sent_at{};
  };
  void expire_requests(MipSink& sink, SteadyTime t);
  void watch_external_server(MipSink& sink);
  // A request lost with a dead server, until it is answered by a later one (or no longer wanted).
  struct Lost {
    bool resent = false;
    SteadyTime resent_at{};
  };
  class TimedSink;   // forwards to the renderer's sink and measures the time spent there
  class IpcScope;    // measures one client call into the current frame's IPC time
  void note_answered(uint64_t k);
  uint64_t overdue_lost(SteadyTime t) const;

  StreamClient() = default;
  SteadyTime now() const;
  void attach_rings();
  void ring_doorbell();
  void flush_releases();
  void release_slot(SlotIndex slot);
  void supervise(MipSink& sink);
  void on_server_gone(MipSink& sink, const std::string& why);
  // A server died by signal `signal`: if it is a crash signal, charges the textures its workers were loading
  // (ServerBlock::loading; before the segment is reset) and quarantines those charged often enough.
  void charge_crash(int signal);
  // The same for a server we killed because it hung while serving (its heartbeat stalled): a texture whose
  // load blocks the server (a file that blocks every read, a stuck mount) is charged like one that crashes it.
  void charge_hang();
  // Charges the textures in ServerBlock::loading with one death described by `how` ("died by signal 11").
  void charge_loading(const std::string& how);
  // Fails (kCorrupt) the requests of quarantined textures refused since the last poll.
  void fail_quarantined_requests(MipSink& sink);
  void protocol_error(const std::string& what);
  // Returns false when the sink had no room (the completion is held).
  bool deliver(const CheckedCompletion& c, MipSink& sink);
  void handle_record(const CompletionRecord& record, MipSink& sink, size_t& mips);
  bool accepting_requests() const;
  // The request ring's read position as published by the server, checked against ours (the ring itself
  // only notices an impossible position when it pushes, and a full-looking ring never pushes).
  std::optional<uint64_t> server_read_position() const;
  static constexpr uint64_t kNoPosition = ~0ull;
  // A slot we released whose kReleaseSlot the server has not read yet (clears the mark once it has).
  bool slot_in_transit(uint32_t slot);
  static uint64_t key(TextureId texture, MipLevel mip) { return (uint64_t{texture.value} << 32) | mip.value; }

  Config config_;
  StreamClientOptions options_;
  std::vector<TextureShape> shapes_;
  std::unique_ptr<Segment> segment_;
  std::unique_ptr<ServerProcess> process_;  // null when spawn_server is false
  SpscRingProducer<RequestRecord> requests_;
  SpscRingConsumer<CompletionRecord> completions_;
  Generation generation_{0};
  std::unordered_map<uint64_t, InFlight> in_flight_;
  std::vector<uint8_t> slot_held_;          // by slot index: handed to us and not yet handed back
  std::deque<SlotIndex> release_queue_;     // held slots whose kReleaseSlot found no room in the ring
  // By slot: request-ring position of the kReleaseSlot that handed it back (kNoPosition: none pending). The
  // slot is the server's only once it has read that record; naming it in a completion earlier is a violation.
  std::vector<uint64_t> release_pos_;
  std::optional<CheckedCompletion> held_;  // passed every check; the sink had no room
  uint32_t release_reserve_ = 0;            // request-ring records kept free for releases
  bool broken_ = false;                     // external server broke a ring
  StreamStats stats_;
  // ServerBlock counters of servers that have died (the block is zeroed by the reset).
  uint64_t past_hits_ = 0, past_misses_ = 0, past_bytes_read_ = 0, past_cancelled_ = 0;
  std::string last_server_exit_;
  std::unordered_map<uint64_t, Lost> lost_;
  IpcTimeHistogram ipc_time_;
  uint64_t frame_ipc_ns_ = 0;   // the open frame's client time so far
  bool frame_open_ = false;
  uint64_t sink_ns_ = 0;        // time inside the sink during the current client call
  int ipc_depth_ = 0;           // nested client calls (poll → restart paths) count once
  SteadyTime next_expiry_scan_{};
  // server.spawn = false: when watch_external_server() looks at the standalone server's identity next.
  static constexpr std::chrono::milliseconds kExternalServerCheck{100};
  SteadyTime next_external_check_{};
  static constexpr std::chrono::seconds kExternalUnservedWarning{3};
  SteadyTime external_unserved_since_{};  // since when no server has held the segment ({}: one does)
  bool external_unserved_told_ = false;
  std::unordered_map<uint32_t, uint32_t> crash_charges_;  // texture id → crashes while it was being loaded
  std::unordered_set<uint32_t> quarantined_;              // texture ids
  std::vector<uint64_t> quarantine_refused_;              // keys refused by try_request, failed at next poll
  std::unordered_set<uint64_t> quarantine_refused_set_;   // the same keys: each failed once per poll
};

}  // namespace texstream
