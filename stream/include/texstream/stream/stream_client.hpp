#pragma once
// The renderer's end of the shared-memory protocol: it creates the segment, has texstream-server spawned
// and supervised (ServerSupervisor), sends load requests, and receives, validates and hands over completed
// mips. No Vulkan: the renderer gives it a MipSink that says where a mip's bytes go (e.g. a mapped staging
// buffer) and what to do with them once checked.
//
// Once per frame, never blocking (DESIGN.md: nothing on the frame path waits on the server):
//   client.begin_cycle();                       // a streaming cycle starts: new Generation
//   states.run_cycle(list, s, b, client.sender(), max_mips_per_cycle);   // Algorithm 1 → kLoad requests
//   client.poll(sink, budget);                  // heartbeat, server liveness, completions → sink
//
// Pages of page files (issue 28) travel the same way: set_page_files() registers the files (the renderer reads
// their headers and indexes itself) and a PageSink; try_request_page() sends a kLoadPage; poll() hands the
// answers to the PageSink, validated against the registered file as mips are against the texture table.
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
// Three parts: this client (requests, completions, validation, slot ownership) over the protocol's
// RendererEndpoint; ServerSupervisor (server_supervisor.hpp: spawn, reap, watchdog, restart, a standalone
// server's death); CrashQuarantine (crash_quarantine.hpp: which texture a crash is charged to).
//
// Single-threaded: the renderer's frame thread makes every call.
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/common/ids.hpp"
#include "texstream/common/result.hpp"
#include "texstream/protocol/completion_check.hpp"
#include "texstream/protocol/records.hpp"
#include "texstream/protocol/renderer_endpoint.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/protocol/spsc_ring.hpp"
#include "texstream/stream/crash_quarantine.hpp"
#include "texstream/stream/mip_sink.hpp"
#include "texstream/stream/page_requests.hpp"
#include "texstream/stream/page_sink.hpp"
#include "texstream/stream/server_process.hpp"
#include "texstream/stream/server_supervisor.hpp"
#include "texstream/stream/stream_stats.hpp"
#include "texstream/stream/texture_states.hpp"
#include "texstream/stream/texture_table.hpp"

namespace texstream::stream {

// Why a request was or was not sent.
enum class RequestOutcome : uint8_t {
  kSent,
  kAlreadyInFlight,  // that (texture, mip) is still in flight
  kInFlightLimit,    // stream.max_requests_in_flight reached
  kRingFull,         // no room in the request ring (room is kept for slot releases)
  kNoServer,         // the server is dead, backing off or in colormap-only mode
  kUnknownTexture,   // id outside the texture table
  kBadMip,           // mip level >= the texture's mip count
  kQuarantined,      // the texture was being loaded when the server crashed twice: failed (kCorrupt) at next poll
  kUnknownPageFile,  // a page of a file index set_page_files() did not register
  kPageNotStored,    // the page lies outside its file's quadtree or is not stored (ask for its parent)
  kPageTooLarge,     // the page's bytes do not fit a staging slot (protocol.staging_slot_bytes)
};
const char* to_string(RequestOutcome outcome);
// kSent and kQuarantined (answered kCorrupt at the next poll) → kSent; other outcomes about this one
// (texture, mip) → kSkip; outcomes about the whole pipe → kStop.
SendResult to_send_result(RequestOutcome outcome);

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
  static constexpr uint32_t kQuarantineAfterCrashes = CrashQuarantine::kQuarantineAfterCrashes;
  // Removes stale "texstream-" segments, creates this one (protocol.segment_name or "texstream-<pid>",
  // sized from `config.protocol`), and spawns the server (unless options.spawn_server is false) with
  // `--scene scene_dir`, `--config config_file` (if not empty) and each override as `--set`.
  // `shapes` is the scene's texture table, indexed by texture id.
  static Result<std::unique_ptr<StreamClient>> start(const Config& config, TextureTable shapes,
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

  // Registers the page files pages are requested from (index = file id: 0 = the scene's ground) and the sink
  // their answers go to; the renderer opens each page file's header and index itself (PageFile::open). Requests
  // in flight stay: their answers are checked against the new files and go to the new sink (a page held for
  // room in the old sink is dropped, its slot handed back, when its file is no longer registered). `sink` must
  // be set when `files` is not empty, and outlive its registration.
  void set_page_files(std::vector<std::shared_ptr<const pages::PageFile>> files, PageSink* sink);
  // Pushes a kLoadPage for `page` of page file `file` with the current generation. Never blocks. Pages and
  // mips share stream.max_requests_in_flight and the request ring.
  RequestOutcome try_request_page(uint32_t file, pages::PageId page, float priority);
  bool page_in_flight(uint32_t file, pages::PageId page) const { return pages_.in_flight(PageRequest{file, page}); }

  // Once per frame: bumps RendererBlock.heartbeat, pushes queued slot releases, supervises the server
  // (reap, watchdog, restart), then takes completions off the ring and hands at most `max_mips` payloads
  // to `sink` — pages to the registered PageSink, counted against `max_mips` as mips are (statuses without
  // payload are not counted against it).
  void poll(MipSink& sink, size_t max_mips);
  // For a caller with nothing to do until completions arrive (lock-step frames, preloads): blocks at most
  // `timeout`, returns at once when one waits (the completion bell: no system call on either side while
  // completions flow). Then poll().
  void wait_for_completions(std::chrono::microseconds timeout);

  StreamStats stats() const;
  const IpcTimeHistogram& ipc_time() const { return ipc_time_; }
  // `key value` lines: every StreamStats counter and the IPC-time quantiles. Written by the destructor to
  // $TEXSTREAM_STREAM_STATS when that is set (texstream-chaos reads it; the renderer's summary.json is
  // written elsewhere).
  std::string stats_text() const;
  bool in_flight(TextureId texture, MipLevel mip) const;
  // stats()'s standalone_refused_by and server_refusals_before_attach without building the whole StreamStats
  // (the renderer asks every frame; stats() counts held slots and scans the lost requests).
  uint32_t standalone_refused_by() const { return supervisor_->standalone_refused_by(); }
  uint64_t server_refusals_before_attach() const { return supervisor_->server_refusals_before_attach(); }
  // Empty if a server is attached to the segment now; else why not, for an error that has to say it.
  std::string unattached_reason() const { return supervisor_->unattached_reason(); }
  bool quarantined(TextureId texture) const { return quarantine_.quarantined(texture); }
  const CrashQuarantine& quarantine() const { return quarantine_; }
  const Segment& segment() const { return *segment_; }
  Segment& segment() { return *segment_; }
  int server_pid() const { return supervisor_->server_pid(); }
  // How the last spawned server ended ("pid 12 exited with status 2"); empty if none has.
  const std::string& last_server_exit() const { return supervisor_->last_server_exit(); }

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
  // A request lost with a dead server, until it is answered by a later one (or no longer wanted).
  struct Lost {
    bool resent = false;
    SteadyTime resent_at{};
  };
  class TimedSink;        // forwards to the renderer's sink and measures the time spent there
  class IpcScope;         // measures one client call into the current frame's IPC time
  class SupervisorHooks;  // what the supervisor asks of us, with the current call's sink
  void note_answered(uint64_t k);
  uint64_t overdue_lost(SteadyTime t) const;

  StreamClient() = default;
  SteadyTime now() const;
  void attach_rings();
  void flush_releases();
  void release_slot(SlotIndex slot);
  void supervise(MipSink& sink);
  void on_server_gone(MipSink& sink, const std::string& why);
  void protocol_error(const std::string& what);
  // Returns false when the sink had no room (the completion is held).
  bool deliver(const CheckedCompletion& c, MipSink& sink);
  bool deliver_page(const CheckedCompletion& c);
  void handle_record(const CompletionRecord& record, MipSink& sink, size_t& mips);
  void handle_page_record(const CheckedCompletion& c, size_t& delivered);
  // A kOk record's slot, taken from the ring: false (with `why`) when the server cannot have handed it to us.
  bool take_slot(SlotIndex slot, std::string& why);
  // Tells the page sink (if any) that `r` ended without a payload, and counts it.
  void fail_page(PageRequest r, CompletionStatus status);
  size_t requests_in_flight() const { return in_flight_.size() + pages_.in_flight_count(); }
  // The request ring's read position as published by the server, checked against ours (the ring itself
  // only notices an impossible position when it pushes, and a full-looking ring never pushes).
  std::optional<uint64_t> server_read_position() const;
  static constexpr uint64_t kNoPosition = ~0ull;
  // A slot we released whose kReleaseSlot the server has not read yet (clears the mark once it has).
  bool slot_in_transit(uint32_t slot);
  static uint64_t key(TextureId texture, MipLevel mip) { return (uint64_t{texture.value} << 32) | mip.value; }

  Config config_;
  StreamClientOptions options_;
  TextureTable shapes_;  // shared with the other users of the scene's table
  std::unique_ptr<Segment> segment_;
  std::unique_ptr<ServerSupervisor> supervisor_;  // whoever serves the segment: spawned or standalone
  CrashQuarantine quarantine_;
  RendererEndpoint endpoint_;  // the rings and the doorbell; rebuilt after every reset
  Generation generation_{0};
  std::unordered_map<uint64_t, InFlight> in_flight_;
  PageRequests pages_;              // the registered page files, the page sink, the pages in flight
  std::vector<uint8_t> slot_held_;  // by slot index: handed to us and not yet handed back
  // By slot: request-ring position of the kReleaseSlot that handed it back (kNoPosition: none pending). The
  // slot is the server's only once it has read that record; naming it in a completion earlier is a violation.
  std::vector<uint64_t> release_pos_;
  std::optional<CheckedCompletion> held_;  // passed every check; the sink had no room
  uint32_t release_reserve_ = 0;           // request-ring records kept free for releases
  StreamStats stats_;
  // ServerBlock counters of servers that have died (the block is zeroed by the reset).
  uint64_t past_hits_ = 0, past_misses_ = 0, past_bytes_read_ = 0, past_cancelled_ = 0, past_syscalls_ = 0;
  std::unordered_map<uint64_t, Lost> lost_;
  IpcTimeHistogram ipc_time_;
  uint64_t frame_ipc_ns_ = 0;  // the open frame's client time so far
  bool frame_open_ = false;
  uint64_t sink_ns_ = 0;  // time inside the sink during the current client call
  int ipc_depth_ = 0;     // nested client calls (poll → restart paths) count once
  SteadyTime next_expiry_scan_{};
};

}  // namespace texstream::stream
