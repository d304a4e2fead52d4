#pragma once
// The texture server (DESIGN.md "Texture server", seed 002 §3.2/§4.3): serves one renderer through one shared
// segment. One dispatcher thread — the caller of run() — is the only consumer of the request ring and the
// only producer of the completion ring; it validates every record, keeps the pending loads in a priority heap,
// owns the staging slots, serves RAM-cache hits itself and hands misses to a small worker pool.
//
// Every valid kLoad gets exactly one completion: kOk (the slot is the renderer's until its kReleaseSlot),
// kNotFound, kCorrupt, kIoError, kTimedOut (a remote origin did not answer in time), kCancelled (coalesced
// with a duplicate or superseded by a newer generation before it started), or kUnfilled (it needs a remote
// fetch and the queue of waiting remote fetches is full: the renderer asks again in a later cycle, seed 002
// §4.3's feedback path).
//
// Bimodal access (seed 002 §3.2, issue 4): a miss first goes to the local workers, which read only what is on
// this machine (local files, disk-cache entries). One that needs the remote or slow origin is handed to a
// separate pool of server.remote_fetches_in_flight threads, so slow fetches never occupy the workers that
// serve disk hits, and the dispatcher serves RAM hits throughout. While those threads are busy, remote loads
// wait in their own priority queue without a staging slot (at most kRemotePendingLimit, then kUnfilled); like
// the main queue it is cut back to the renderer's newest cycle whenever a new batch arrives (kCancelled:
// stale), so a slow link never builds up a backlog the renderer no longer wants. Invalid records are logged and
// dropped. A full completion ring never blocks and never drops: completions wait in a local queue.
//
// Pages (kLoadPage, issue 28): a page of one of the scene's page files (PageLoader: today scene.json's ground)
// is a load like a mip's. It shares the heap (its key cannot be a mip's: load_request.hpp), generations,
// coalescing and cancellation, the staging slots, the inline reads of local data, and the hand-off of what is
// not on this machine to the remote-fetch workers. It never touches the RAM cache, and is not charged to a
// texture in ServerBlock::loading. A bad one (unknown file, a page outside the quadtree or not stored) is
// answered kNotFound at once.
#include <atomic>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/liveness.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/server/cache/mip_cache.hpp"
#include "texstream/server/dispatch/request_scheduler.hpp"
#include "texstream/server/dispatch/slot_pool.hpp"
#include "texstream/server/dispatch/worker_pool.hpp"
#include "texstream/server/load/mip_loader.hpp"
#include "texstream/server/load/page_loader.hpp"
#include "texstream/server/load/server_stats.hpp"
#include "texstream/server/storage/storage.hpp"

namespace texstream::server {

enum class RunOutcome {
  kStopped,       // the stop flag was set
  kRendererDead,  // the renderer that owns the segment exited (or was never alive)
  kPeerCorrupt,   // a ring position published by the renderer is impossible: the protocol is broken
  kSegmentBusy,   // another server holds the segment (its pid is in the ServerBlock): nothing was touched
};
const char* to_string(RunOutcome outcome);

// The scene's texture table: textures.bin mapped read-only, every record checked, no heap copy (16 bytes per
// texture less than a vector: 91 MB at 5.7 M textures; docs/design/host_memory.md). Shared: main.cpp's copy
// serves the first renderer's server.
using SceneTextures = std::shared_ptr<const scene::MappedTextureTable>;

class Server {
 public:
  // The scene's texture table, validated (errors name the file). create() maps it again for each renderer;
  // texstream-server maps it once at start too, so that a wrong scene is refused before it waits.
  static Result<SceneTextures> read_scene(const std::filesystem::path& scene_dir);
  // Maps the scene's texture table (errors name the file), opens the page files scene.json names (a
  // missing or damaged one is an error naming it; PageLoader::open) and attaches to `segment`. The segment and the
  // storage must outlive the server. ErrorCode::kProtocol: the segment's renderer reads another scene (its
  // texture table differs); any other error is this server's configuration or scene.
  // `scene`: the table read_scene() returned for scene_dir, taken instead of checking it again (a city's table
  // is ~90 MB); null: mapped now.
  static Result<std::unique_ptr<Server>> create(Segment& segment, const std::filesystem::path& scene_dir,
                                                const ServerConfig& config, Storage& storage,
                                                SceneTextures scene = nullptr);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Serves until `stop` is set, the renderer dies, or the renderer breaks the ring protocol. Writes the
  // ServerBlock (pid, start time, attached = 1 while running, heartbeat every iteration, statistics).
  // When `print_stats` is given, the loop logs the statistics each time it finds the flag set (and clears
  // it): a SIGUSR1 handler only sets the flag (async-signal-safe), the printing happens here. The statistics
  // are logged once more when run() returns.
  RunOutcome run(const std::atomic<bool>& stop, std::atomic<bool>* print_stats = nullptr);

  MipCacheStats cache_stats() const { return cache_.stats(); }
  // Remote fetches started and loads answered kUnfilled so far (read after run() returned, or as a statistic).
  uint64_t remote_fetches() const { return remote_fetches_.load(std::memory_order_relaxed); }
  uint64_t unfilled() const { return unfilled_.load(std::memory_order_relaxed); }
  const ServerStats& stats() const { return stats_; }
  // The pid that held the segment when run() returned kSegmentBusy.
  uint32_t busy_holder() const { return busy_holder_; }
  // format_stats() of the current counters.
  std::string stats_report() const;

 private:
  Server(Segment& segment, const std::filesystem::path& scene_dir, const ServerConfig& config, Storage& storage,
         SceneTextures textures);

  // One pass of the loop; returns true if anything happened (then the loop does not sleep).
  bool drain_requests();
  void handle_load(const RequestRecord& r);
  void handle_load_page(const RequestRecord& r);
  void handle_release(const RequestRecord& r);
  bool collect_results();
  // A local worker's (or an inline load's) result: finished, or handed on to the remote path if kUnfilled.
  void handle_local_result(const LoadResult& r);
  // The mip's bytes if the dispatcher may load this miss itself (kInlineMissBytes, server.cpp), budget per
  // pass aside; 0 if it may not.
  uint64_t inline_bytes(const LoadRequest& request) const;
  void load_inline(const LoadRequest& request, const scene::TextureRecord& record, uint32_t slot);
  // The job a worker runs for `request` (a page's carries no texture record).
  LoadJob job_of(const LoadRequest& request, uint32_t slot) const;
  // What a worker runs: a mip through the loader, a page through the page files.
  CompletionRecord run_job(const LoadJob& job, bool local_only);
  // dispatch()'s copy of a mip the last inline load holds (MipLoader::serve_held), or from the cache when it
  // was served from there already.
  CompletionRecord serve_held(const LoadRequest& request, const scene::TextureRecord& record, uint32_t slot);
  void finish(const LoadResult& r);
  bool dispatch_remote();
  bool dispatch();
  void complete(const CompletionRecord& c);
  // Pushes one completion into the ring without publishing it (false: the ring is full).
  bool push_completion(const CompletionRecord& c);
  // Makes the completions pushed so far visible to the renderer: one release-store of the ring position per
  // pass instead of one per record (texstream-bench server: the per-record store and the load of the
  // renderer's read position were a share of a hit's ring cost).
  void publish_completions();
  bool flush_completions();
  void idle_wait();
  void update_gauges();
  void record_latency(LatencyHistogram& histogram, uint64_t received_ns);

  Segment& segment_;
  Storage& storage_;
  std::filesystem::path scene_dir_;
  ServerConfig config_;
  SceneTextures table_;                             // holds the mapping textures_ reads
  std::span<const scene::TextureRecord> textures_;  // table_->textures
  SpscRingConsumer<RequestRecord> requests_;
  SpscRingProducer<CompletionRecord> completions_;
  ServerStats stats_;
  std::unique_ptr<Storage> rate_limited_;  // server.rate_limit_mb_s > 0: wraps the storage given to create()
  MipCache cache_;
  MipLoader loader_;
  std::unique_ptr<PageLoader> pages_;  // set by create() before run()
  RequestScheduler scheduler_;
  RequestScheduler remote_pending_;  // remote loads waiting for a remote-fetch worker (no slot held)
  SlotPool slots_;
  uint32_t loads_in_flight_ = 0;   // jobs of the local workers
  uint32_t remote_in_flight_ = 0;  // jobs of the remote-fetch workers (≤ server.remote_fetches_in_flight)
  std::atomic<uint64_t> remote_fetches_{0};
  std::atomic<uint64_t> unfilled_{0};
  uint32_t busy_holder_ = 0;
  std::deque<CompletionRecord> overflow_;       // completions waiting for room in the ring
  uint32_t unpublished_completions_ = 0;        // pushed into the ring, not yet published (this pass's)
  bool publish_each_completion_ = false;        // fault injection: publish per record (kAfterRingPush)
  std::vector<LoadRequest> cancelled_scratch_;  // reused each iteration: no allocation when warm
  std::vector<LoadResult> results_scratch_;
  std::vector<MipKey> drained_keys_;       // the loads of the pass's drained batch (MipCache::prefetch_index)
  std::vector<uint64_t> hits_unrecorded_;  // receive times of hits served, latency not yet recorded
  uint64_t pass_now_ns_ = 0;               // steady clock at the start of the loop's current pass
  // How long the dispatcher's recent idle gaps lasted until work came (moving average, ns): idle_wait() spins
  // only while it is below kSpinBeforeSleep, i.e. while a spin is likely to find the next request.
  uint64_t idle_gap_ns_ = 0;
  ShmAtomic<uint32_t>* inline_loading_ = nullptr;  // the dispatcher's crash-attribution word (null: no inline loads)
  std::vector<bool> inline_ok_;                    // per texture: may be loaded inline (not remote, not slow)
  uint64_t clock_generation_ = 0;                  // last generation forwarded to the cache policy (Eq. 4 clock)
  std::unique_ptr<WorkerPool> workers_;            // last members: their threads die before what they use
  std::unique_ptr<WorkerPool> remote_workers_;
};

}  // namespace texstream::server
