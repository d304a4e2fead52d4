#include "texstream/server/dispatch/server.hpp"
#include "texstream/server/support/fault_point.hpp"

#include <unistd.h>

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>

#include "texstream/common/cpu_relax.hpp"
#include "texstream/protocol/checksum.hpp"
#include "texstream/protocol/doorbell.hpp"
#include "texstream/server/storage/rate_limited_storage.hpp"

namespace texstream::server {

namespace {

// While loads are in flight the dispatcher naps at most this long: a worker's wake-up can slip in between the
// dispatcher's last check and its futex_wait (the doorbell word, which workers do not write, has not changed),
// so this bounds the cost of that race. 1 ms against loads of 0.1–10 ms.
constexpr std::chrono::microseconds kBusyWait{1000};
// The same race with only remote fetches in flight costs a late remote result at most this long: 10 ms
// against fetches of 20 ms to seconds, and 100 instead of 1000 wake-ups per second while a slow link trickles.
constexpr std::chrono::microseconds kRemoteBusyWait{10000};

// Loads handed to the pool per worker. With 1, every miss costs a dispatcher round trip (worker result →
// futex wake → dispatcher → condition variable → worker) before the worker starts its next read: measured
// with texstream-bench server on the 2-core machine, misses ran at 0.07x plain read(). A second job per
// worker lets it go on at once; the cost is that up to this many jobs per worker can no longer be superseded.
constexpr uint32_t kJobsPerWorker = 2;

// The dispatcher loads a local miss up to this size itself: a hand-off to a worker costs two wake-ups, most of
// a miss on 2 cores (1 MiB rather than 64 KiB: misses +8-10 %).
// Measurements, the rules around it and what was tried: docs/design/inline_miss_loads.md.
constexpr uint64_t kInlineMissBytes = 1 << 20;
// An inline load that took longer than this (a disk read, a decode) marks its texture as not for inline loads.
constexpr uint64_t kInlineSlowNs = 250'000;
// Inline loads per pass end after this many, or once they asked for kInlineMissBytes, so that worker results,
// completions and the request ring are still looked at every ~100 us at most while the dispatcher loads.
constexpr uint32_t kInlineMissesPerPass = 4;

// Completions are published in groups of at most this many (and at the end of every pass): one release-store
// per group, while the renderer can already take the first ones and hand their slots back as the dispatcher
// copies the rest of a batch (publishing only at the end of a pass of 32 hits left it idle meanwhile).
constexpr uint32_t kPublishBatch = 8;

// After a busy pass, poll this long (spinning, no system call) before sleeping on the futex: a renderer streaming
// a batch pushes again within microseconds, and a futex sleep + wake costs two syscalls and a context switch
// per batch. Bounded so an idle server costs nothing.
constexpr std::chrono::microseconds kSpinBeforeSleep{50};

// The loop asks the kernel whether the renderer is alive (a poll() on its pidfd) at most this often, busy or
// idle (a pass after a sleep longer than this asks at once). One syscall per pass was one per handful of hits
// (texstream-bench server: passes take 2–20 µs). 1 ms is nothing against the 9–75 ms it takes to notice a death anyway.
constexpr uint64_t kLivenessCheckNs = 1'000'000;

// Remote loads that may wait for a remote-fetch worker. They hold no staging slot and live at most until the
// renderer's next batch; this bounds the queue's memory against a renderer that floods one cycle. 256 = the
// default stream.max_requests_in_flight: one whole cycle of requests.
constexpr size_t kRemotePendingLimit = 256;

uint64_t steady_now_ns() {
  return static_cast<uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
          .count());
}

}  // namespace

const char* to_string(RunOutcome outcome) {
  switch (outcome) {
    case RunOutcome::kStopped:
      return "stopped";
    case RunOutcome::kRendererDead:
      return "renderer dead";
    case RunOutcome::kPeerCorrupt:
      return "renderer broke the ring protocol";
    case RunOutcome::kSegmentBusy:
      return "segment held by another server";
  }
  return "?";
}

Result<SceneTextures> Server::read_scene(const std::filesystem::path& scene_dir) {
  Result<scene::MappedTextureTable> mapped = scene::map_texture_table(scene_dir);
  if (!mapped.ok()) return mapped.error();
  const std::span<const scene::TextureRecord> textures = mapped->textures;
  // map_texture_table validates extents and mip counts; the format is re-checked here because everything
  // downstream casts it.
  for (size_t i = 0; i < textures.size(); ++i) {
    if (!texel_format_from_raw(textures[i].format)) {
      return make_error(ErrorCode::kCorrupt, "texture table of '" + scene_dir.string() + "': texture " +
                                                 std::to_string(i) + " has unknown format " +
                                                 std::to_string(textures[i].format));
    }
  }
  return SceneTextures(std::make_shared<const scene::MappedTextureTable>(std::move(mapped).value()));
}

Result<std::unique_ptr<Server>> Server::create(Segment& segment, const std::filesystem::path& scene_dir,
                                               const ServerConfig& config, Storage& storage, SceneTextures scene) {
  if (config.worker_threads < 1 || config.worker_threads > 64) {
    return make_error(ErrorCode::kInvalidArgument,
                      "server.worker_threads must be in [1, 64], not " + std::to_string(config.worker_threads));
  }
  if (config.ram_cache_bytes < 0) {
    return make_error(ErrorCode::kInvalidArgument, "server.ram_cache_bytes must be >= 0");
  }
  if (!(config.idle_wait_ms > 0)) return make_error(ErrorCode::kInvalidArgument, "server.idle_wait_ms must be > 0");
  if (config.remote_fetches_in_flight < 1 || config.remote_fetches_in_flight > 16) {
    return make_error(ErrorCode::kInvalidArgument, "server.remote_fetches_in_flight must be in [1, 16], not " +
                                                       std::to_string(config.remote_fetches_in_flight));
  }
  Result<SceneTextures> table = scene ? Result<SceneTextures>(std::move(scene)) : read_scene(scene_dir);
  if (!table.ok()) return table.error();
  const std::span<const scene::TextureRecord> textures = (*table)->textures;
  // The renderer states its texture table in the header: a server reading another scene would answer every
  // request for textures the renderer does not have (refused one by one as protocol errors). Refused here.
  if (const SegmentHeader& h = segment.header(); h.texture_table_fingerprint != 0) {
    uint64_t fingerprint = kTextureTableSeed;
    for (const scene::TextureRecord& t : textures) {
      fingerprint = texture_table_step(fingerprint, t.width, t.height, t.mip_count, t.format);
    }
    if (h.texture_count != textures.size() || h.texture_table_fingerprint != fingerprint) {
      // kProtocol: this renderer's segment is not one this server can serve (main.cpp tells it from a bad
      // configuration: a standalone server waits for the next renderer).
      return make_error(ErrorCode::kProtocol,
                        fmt::format("segment '{}' was made by a renderer reading a texture table of {} textures "
                                    "(fingerprint {:016x}), but this server's scene '{}' has {} (fingerprint "
                                    "{:016x}): the two read different scenes (scene.dir, --scene, storage.origin)",
                                    segment.name(), h.texture_count, h.texture_table_fingerprint, scene_dir.string(),
                                    textures.size(), fingerprint));
    }
  }
  if (!(config.rate_limit_mb_s >= 0)) {
    return make_error(ErrorCode::kInvalidArgument, "server.rate_limit_mb_s must be >= 0");
  }
  std::unique_ptr<Server> server(new Server(segment, scene_dir, config, storage, std::move(table).value()));
  // Through the storage the loads read (rate limit included), so that pages come through every tier as mips do.
  Result<std::unique_ptr<PageLoader>> pages =
      PageLoader::open(scene_dir, server->rate_limited_ ? *server->rate_limited_ : storage, server->stats_);
  if (!pages.ok()) return pages.error();
  server->pages_ = std::move(pages).value();
  return server;
}

Server::Server(Segment& segment, const std::filesystem::path& scene_dir, const ServerConfig& config, Storage& storage,
               SceneTextures textures)
    : segment_(segment),
      storage_(storage),
      scene_dir_(scene_dir),
      config_(config),
      table_(std::move(textures)),
      textures_(table_->textures),
      requests_(segment.request_consumer()),
      completions_(segment.completion_producer()),
      rate_limited_(config.rate_limit_mb_s > 0 ? std::make_unique<RateLimitedStorage>(storage, config.rate_limit_mb_s,
                                                                                      &stats_.rate_limit_wait_us)
                                               : nullptr),
      // Eq. 4's quadtree level over this server's texture table: a texture's coarsest (1x1) mip is the root.
      cache_(static_cast<uint64_t>(config.ram_cache_bytes),
             make_eviction_policy(config.cache_policy,
                                  [this](MipKey key) {
                                    const scene::TextureRecord& t = textures_[key.texture().value];
                                    return t.mip_count - 1 - std::min(key.mip().value, t.mip_count - 1);
                                  }),
             // Misses read into a warm arena of the budget, pre-faulted at idle priority (cache_arena.hpp).
             MipCacheOptions{.arena = true, .prefault = ArenaPrefault::kBackground}),
      loader_(scene_dir, rate_limited_ ? *rate_limited_ : storage, cache_, segment.server_block(), stats_),
      slots_(segment.slot_count()) {
  cancelled_scratch_.reserve(256);
  results_scratch_.reserve(64);
  hits_unrecorded_.reserve(256);
  drained_keys_.reserve(256);
  if (fault_injection_enabled()) completions_.set_mid_push_hook([] { fault_point(FaultPoint::kMidRingPush); });
  publish_each_completion_ = fault_injection_enabled();
  // Only a sleeping dispatcher is woken: a wake per result was a syscall per miss, mostly for a dispatcher
  // that was awake anyway (Doorbell::wake_sleeper: the pool publishes its result seq_cst before).
  auto wake = [doorbell = Doorbell(segment_)] { doorbell.wake_sleeper(); };
  // Crash attribution (ServerBlock::loading, read by the renderer after a crash): the dispatcher's inline
  // loads take word 0 (none with a rate limit: every load then goes through the token bucket on a worker), the
  // local workers' words follow, the remote fetch workers' after them; threads beyond kLoadingWords are not
  // recorded. The dispatcher's word came after the workers' before, and with none left (8 words: e.g.
  // server.worker_threads = 8 and 4 remote fetches) there were no inline loads at all, and local misses went
  // through the workers' hand-off: texstream-bench server --quick --phases misses with 8 workers gave
  // miss_vs_read 0.126, now 0.517 (0.493 with the default 2 workers, same session).
  const std::span<ShmAtomic<uint32_t>> loading(segment_.server_block().loading);
  const size_t first_worker_word = rate_limited_ ? 0 : 1;
  if (!rate_limited_) inline_loading_ = &loading[0];
  const size_t local_words =
      std::min<size_t>(loading.size() - first_worker_word, static_cast<size_t>(config.worker_threads));
  inline_ok_.assign(textures_.size(), true);
  workers_ = std::make_unique<WorkerPool>(
      static_cast<uint32_t>(config.worker_threads),
      [this](const LoadJob& job) { return run_job(job, /*local_only=*/true); }, wake,
      loading.subspan(first_worker_word, local_words), &stats_.syscalls);
  remote_workers_ = std::make_unique<WorkerPool>(
      static_cast<uint32_t>(config.remote_fetches_in_flight),
      [this](const LoadJob& job) { return run_job(job, /*local_only=*/false); }, wake,
      loading.subspan(first_worker_word + local_words), &stats_.syscalls);
}

Server::~Server() {
  // A remote fetch can take up to storage.request_timeout_ms: cut transfers short, then join before the
  // members the workers use go away. Only then: with nothing remote in flight the storage is not touched
  // (a caller may already have destroyed a storage it no longer reads through).
  const bool remote_busy = remote_in_flight_ > 0;
  if (remote_busy) storage_.cancel_all();
  remote_workers_.reset();
  workers_.reset();
  if (remote_busy) storage_.resume();
}

RunOutcome Server::run(const std::atomic<bool>& stop, std::atomic<bool>* print_stats) {
  const SyscallAccount account(stats_.syscalls);  // this thread's kernel crossings are the server's
  ServerBlock& block = segment_.server_block();
  RendererBlock& renderer = segment_.renderer_block();
  const int self = static_cast<int>(::getpid());
  // One server per segment: its rings have one consumer and one producer each. The pid word is the claim:
  // 0 after creation and after the renderer's reset of a dead server's block; a server leaves it set when it
  // detaches. A second server (a standalone one and the renderer's own child on one name) finds it taken and
  // touches nothing; so does a server whose predecessor died before the renderer reset the block.
  uint32_t holder = 0;
  if (!block.pid.v.compare_exchange_strong(holder, static_cast<uint32_t>(self), std::memory_order_acq_rel) &&
      holder != static_cast<uint32_t>(self)) {
    busy_holder_ = holder;
    return RunOutcome::kSegmentBusy;
  }
  // relaxed: published to the renderer by the release-store of `attached` below.
  block.start_time.v.store(process_start_time(self).value_or(0), std::memory_order_relaxed);
  block.attached.v.store(1, std::memory_order_release);  // pairs with the renderer's acquire-load

  // A pid alone is not an identity: first check that the pid in the segment is still the process that
  // created it (pid + start time), then watch that pid through a pidfd — the kernel tells us when it exits.
  const int renderer_pid = static_cast<int>(renderer.pid);
  RunOutcome outcome = RunOutcome::kStopped;
  PidWatch watch;
  if (!process_alive(renderer_pid, renderer.start_time)) {
    spdlog::warn("the renderer (pid {}) that created segment '{}' is gone", renderer_pid, segment_.name());
    outcome = RunOutcome::kRendererDead;
  } else {
    watch = PidWatch(renderer_pid);
  }

  uint64_t last_liveness_check = 0;
  while (outcome == RunOutcome::kStopped && !stop.load(std::memory_order_relaxed)) {
    block.heartbeat.v.fetch_add(1, std::memory_order_relaxed);  // relaxed: progress counter, no data behind it
    pass_now_ns_ = steady_now_ns();
    if (pass_now_ns_ - last_liveness_check >= kLivenessCheckNs) {
      last_liveness_check = pass_now_ns_;
      loader_.log_left_out_timeouts();
      if (watch.dead()) {
        spdlog::info("the renderer (pid {}) exited", renderer_pid);
        outcome = RunOutcome::kRendererDead;
        break;
      }
    }
    bool busy = flush_completions();
    busy |= drain_requests();
    busy |= collect_results();
    busy |= dispatch_remote();  // first: a slot freed by a remote result goes to the next remote fetch
    busy |= dispatch();
    busy |= flush_completions();
    publish_completions();  // one release-store for the pass's completions (before any sleep below)
    if (requests_.error() != RingError::kNone || completions_.error() != RingError::kNone) {
      spdlog::error("segment '{}': the renderer published an impossible ring position; giving up the segment",
                    segment_.name());
      outcome = RunOutcome::kPeerCorrupt;
      break;
    }
    update_gauges();
    // relaxed: the flag carries no data; the handler that set it ran on this process.
    if (print_stats && print_stats->exchange(false, std::memory_order_relaxed)) {
      spdlog::info("statistics (SIGUSR1):\n{}", stats_report());
    }
    if (!busy) idle_wait();
  }
  block.attached.v.store(0, std::memory_order_release);  // pairs with the renderer's acquire-load
  loader_.log_left_out_timeouts(/*now_or_never=*/true);
  spdlog::info("{}: {} completions\n{}", to_string(outcome), block.completions.v.load(std::memory_order_relaxed),
               stats_report());
  return outcome;
}

std::string Server::stats_report() const { return format_stats(stats_, cache_.stats()); }

void Server::update_gauges() {
  stats_.pending.set(scheduler_.size());
  stats_.in_flight.set(loads_in_flight_);
  stats_.overflow.set(overflow_.size());
  // relaxed: statistic; the dispatcher is the block's only writer.
  segment_.server_block().syscalls.v.store(stats_.syscalls.total(), std::memory_order_relaxed);
}

void Server::record_latency(LatencyHistogram& histogram, uint64_t received_ns) {
  const uint64_t now = steady_now_ns();
  histogram.record_one_writer(now > received_ns ? (now - received_ns) / 1000 : 0);  // the dispatcher's alone
}

bool Server::drain_requests() {
  bool any = false;
  // Bounded per pass so that a flood of requests cannot starve completions and the heartbeat.
  const uint32_t budget = segment_.header().request_capacity;
  for (uint32_t i = 0; i < budget; ++i) {
    const std::optional<RequestRecord> r = requests_.try_pop_deferred();  // handed back below, once
    if (!r) break;
    any = true;
    if (r->kind == static_cast<uint32_t>(RequestKind::kLoad)) {
      handle_load(*r);
    } else if (r->kind == static_cast<uint32_t>(RequestKind::kReleaseSlot)) {
      handle_release(*r);
    } else if (r->kind == static_cast<uint32_t>(RequestKind::kLoadPage)) {
      handle_load_page(*r);
    } else {
      spdlog::warn("dropped a request record of unknown kind {}", r->kind);
    }
  }
  requests_.publish();  // one release-store of the read position for the whole batch
  if (!any) return false;
  // The batch's index slots, all at once: a hit's lookup in copy_into() waited for DRAM each time (perf: most of
  // copy_into()'s own time). texstream-bench server --quick --phases hits, 6 alternating runs: 0.52 -> 0.58.
  cache_.prefetch_index(drained_keys_);
  drained_keys_.clear();
  if (scheduler_.newest_generation().value > clock_generation_) {
    clock_generation_ = scheduler_.newest_generation().value;
    cache_.advance_clock(clock_generation_);  // one streaming cycle = one "frame" of seed 002 Eq. 4
  }
  // The batch read now is the renderer's latest cycle: pending requests of older cycles that it did not ask
  // for again are stale (seed 002 §4.3: the server must not get bogged down processing old requests).
  cancelled_scratch_.clear();
  scheduler_.supersede_older_than(scheduler_.newest_generation(), cancelled_scratch_);
  remote_pending_.supersede_older_than(scheduler_.newest_generation(), cancelled_scratch_);
  for (const LoadRequest& c : cancelled_scratch_) {
    segment_.server_block().requests_cancelled.v.fetch_add(1, std::memory_order_relaxed);  // relaxed: statistic
    stats_.add(stats_.cancelled, 1);
    complete(make_completion(c, CompletionStatus::kCancelled));
  }
  return true;
}

void Server::handle_load(const RequestRecord& r) {
  // Validate the copy: the ring's bytes are the renderer's and may be anything.
  if (r.texture_id >= textures_.size()) {
    spdlog::warn("dropped a load of texture {}: the scene has {} textures", r.texture_id, textures_.size());
    return;
  }
  const scene::TextureRecord& t = textures_[r.texture_id];
  if (r.mip_level >= t.mip_count) {
    spdlog::warn("dropped a load of texture {} mip {}: it has {} mips", r.texture_id, r.mip_level, t.mip_count);
    return;
  }
  if (std::isnan(r.priority)) {
    spdlog::warn("dropped a load of texture {} mip {}: priority is NaN", r.texture_id, r.mip_level);
    return;
  }
  ServerBlock& block = segment_.server_block();
  // relaxed: statistic. The dispatcher is its only writer: load + store, no locked read-modify-write.
  block.requests_received.v.store(block.requests_received.v.load(std::memory_order_relaxed) + 1,
                                  std::memory_order_relaxed);
  // The pass's clock reading: a batch is drained in microseconds, and a clock read per request was a
  // measurable share of a hit.
  LoadRequest request{TextureId(r.texture_id), MipLevel(r.mip_level), Generation(r.generation), r.priority};
  request.received_ns = pass_now_ns_;
  const uint64_t bytes = mip_bytes(static_cast<TexelFormat>(t.format), t.width, t.height, r.mip_level);
  if (bytes > segment_.slot_bytes()) {
    spdlog::warn("texture {} mip {}: {} ({}): {} bytes do not fit a staging slot of {} bytes", r.texture_id,
                 r.mip_level, to_string(CompletionStatus::kIoError),
                 scene::texture_path(scene_dir_, request.texture).string(), bytes, segment_.slot_bytes());
    stats_.add(stats_.io_errors, 1);
    complete(make_completion(request, CompletionStatus::kIoError));
    return;
  }
  drained_keys_.push_back(request.key());
  if (const std::optional<LoadRequest> cancelled = scheduler_.add(request)) {
    block.requests_cancelled.v.fetch_add(1, std::memory_order_relaxed);  // relaxed: statistic
    stats_.add(stats_.cancelled, 1);
    complete(make_completion(*cancelled, CompletionStatus::kCancelled));
  }
}

void Server::handle_load_page(const RequestRecord& r) {
  if (std::isnan(r.priority)) {
    spdlog::warn("dropped a load of page file {} level {} page {},{}: priority is NaN", r.texture_id, r.mip_level,
                 r.page_x, r.page_y);
    return;
  }
  ServerBlock& block = segment_.server_block();
  // relaxed: statistic, one writer (as handle_load's).
  block.requests_received.v.store(block.requests_received.v.load(std::memory_order_relaxed) + 1,
                                  std::memory_order_relaxed);
  LoadRequest request{TextureId(r.texture_id), MipLevel(r.mip_level), Generation(r.generation), r.priority};
  request.page = true;
  request.x = r.page_x;
  request.y = r.page_y;
  request.received_ns = pass_now_ns_;
  // Every field checked against the page file before the page is queued (its key needs a level inside the
  // quadtree): a bad request is answered, never dropped, so the renderer does not wait for its timeout.
  if (const CompletionStatus refused = pages_->check(request, segment_.slot_bytes());
      refused != CompletionStatus::kOk) {
    stats_.add(refused == CompletionStatus::kNotFound ? stats_.not_found : stats_.io_errors, 1);
    complete(make_completion(request, refused));
    return;
  }
  if (const std::optional<LoadRequest> cancelled = scheduler_.add(request)) {
    block.requests_cancelled.v.fetch_add(1, std::memory_order_relaxed);  // relaxed: statistic
    stats_.add(stats_.cancelled, 1);
    complete(make_completion(*cancelled, CompletionStatus::kCancelled));
  }
}

void Server::handle_release(const RequestRecord& r) {
  if (!slots_.release_from_renderer(r.slot)) {
    spdlog::warn("dropped a release of slot {}: the renderer does not own it ({} slots)", r.slot, slots_.count());
  }
}

bool Server::collect_results() {
  results_scratch_.clear();
  workers_->take_results(results_scratch_);
  const size_t local_results = results_scratch_.size();
  remote_workers_->take_results(results_scratch_);
  for (size_t i = 0; i < results_scratch_.size(); ++i) {
    const LoadResult& r = results_scratch_[i];
    if (i >= local_results) {
      TS_ASSERT(remote_in_flight_ > 0, "a remote-fetch result with no fetch in flight");
      --remote_in_flight_;
      if (!r.request.page) inline_ok_[r.request.texture.value] = false;  // a remote texture
      finish(r);
      continue;
    }
    TS_ASSERT(loads_in_flight_ > 0, "a worker result with no load in flight");
    --loads_in_flight_;
    handle_local_result(r);
  }
  return !results_scratch_.empty();
}

void Server::handle_local_result(const LoadResult& r) {
  if (r.completion.status != static_cast<uint32_t>(CompletionStatus::kUnfilled)) {
    finish(r);
    return;
  }
  // Not on this machine: the texture's next mips go to the workers (a page's locality is asked per page).
  if (!r.request.page) inline_ok_[r.request.texture.value] = false;
  // The mip is not on this machine. A free remote-fetch worker takes it (keeping the slot); with all of
  // them busy it waits in the remote queue without its slot, or — queue full — the renderer is told to
  // ask again later (seed 002 §4.3: the server must not get bogged down in old requests).
  if (remote_in_flight_ < remote_workers_->threads() && remote_pending_.empty()) {
    ++remote_in_flight_;
    remote_fetches_.fetch_add(1, std::memory_order_relaxed);
    remote_workers_->submit(job_of(r.request, r.slot));
    return;
  }
  slots_.release_unused(r.slot);
  if (r.request.generation.value < scheduler_.newest_generation().value) {
    // Already stale: a newer batch came while the local worker looked. Superseded, like a waiting one.
    stats_.add(stats_.cancelled, 1);
    complete(make_completion(r.request, CompletionStatus::kCancelled));
    return;
  }
  if (remote_pending_.size() >= kRemotePendingLimit) {
    // Full: the renderer asks again in a later cycle.
    unfilled_.fetch_add(1, std::memory_order_relaxed);
    complete(r.completion);
    return;
  }
  if (const std::optional<LoadRequest> dup = remote_pending_.add(r.request)) {
    stats_.add(stats_.cancelled, 1);
    complete(make_completion(*dup, CompletionStatus::kCancelled));
  }
}

uint64_t Server::inline_bytes(const LoadRequest& request) const {
  if (inline_loading_ == nullptr) return 0;
  if (request.page) return pages_->local_bytes(request, kInlineMissBytes);
  if (!inline_ok_[request.texture.value]) return 0;
  const scene::TextureRecord& t = textures_[request.texture.value];
  const uint64_t bytes = mip_bytes(static_cast<TexelFormat>(t.format), t.width, t.height, request.mip.value);
  return bytes <= kInlineMissBytes ? bytes : 0;
}

void Server::load_inline(const LoadRequest& request, const scene::TextureRecord& record, uint32_t slot) {
  // Crash attribution as a worker's (ServerBlock::loading). Relaxed: read only after this process died.
  inline_loading_->v.store(request.texture.value + 1, std::memory_order_relaxed);
  const uint64_t start = steady_now_ns();
  // The dispatcher is the only caller with read_tail: a small mip brings its texture's coarse tail along,
  // and the other levels of the texture that wait in the queue join the same read (they are asked anyway).
  uint32_t wanted = 0;
  for (uint32_t l = 0; l < std::min<uint32_t>(record.mip_count, 32); ++l) {
    if (l != request.mip.value && scheduler_.contains(MipKey(request.texture, MipLevel(l)))) wanted |= 1u << l;
  }
  // hold_read: the levels read along are answered from the read's own bytes while they are the queue's
  // next requests (dispatch(): serve_held), then inserted into the cache together at the end of the pass.
  bool deferred_decode = false;
  const CompletionRecord c = loader_.load(request, record, slot, segment_.slot(slot), /*local_only=*/true,
                                          /*read_tail=*/true, wanted, /*hold_read=*/true, &deferred_decode);
  if (steady_now_ns() - start > kInlineSlowNs) inline_ok_[request.texture.value] = false;
  // A texture that is decoded (TIFF, OpenEXR, a DDS encoding served as RGBA8) or was not found goes to the
  // workers from now on, however fast this load was: a decode must never hold up the hits behind it.
  if (!loader_.serves_raw(request.texture, static_cast<TexelFormat>(record.format))) {
    inline_ok_[request.texture.value] = false;
  }
  inline_loading_->v.store(0, std::memory_order_relaxed);
  if (deferred_decode) {
    // A decode (and perhaps a helper's start) is a worker's job: the hits behind it go on being served.
    inline_ok_[request.texture.value] = false;
    ++loads_in_flight_;
    workers_->submit(LoadJob{request, record, slot});
    return;
  }
  handle_local_result(LoadResult{c, slot, request.received_ns, request});
}

bool Server::dispatch_remote() {
  bool any = false;
  while (!remote_pending_.empty() && remote_in_flight_ < remote_workers_->threads() && slots_.free_count() > 0) {
    const LoadRequest request = *remote_pending_.pop();
    ++remote_in_flight_;
    remote_fetches_.fetch_add(1, std::memory_order_relaxed);
    remote_workers_->submit(job_of(request, *slots_.acquire()));
    any = true;
  }
  return any;
}

void Server::finish(const LoadResult& r) {
  if (r.completion.status == static_cast<uint32_t>(CompletionStatus::kOk)) {
    slots_.hand_to_renderer(r.slot);
    stats_.add(r.request.page ? stats_.pages_ok : stats_.loads_ok, 1);
    record_latency(stats_.miss_latency, r.received_ns);
  } else {
    slots_.release_unused(r.slot);
  }
  complete(r.completion);
}

bool Server::dispatch() {
  bool any = false;
  const uint32_t workers = workers_->threads();
  uint32_t inline_loads = 0;
  uint64_t inline_asked = 0;  // bytes of the pass's inline loads
  while (!scheduler_.empty() && slots_.free_count() > 0) {
    // A RAM-cache hit is always served here at once: a slow read must not hold up a fast hit (seed 002 §3.2,
    // the bimodal access problem). A miss of a local texture up to kInlineMissBytes is loaded here too, at
    // most kInlineMissesPerPass loads or kInlineMissBytes asked per pass; anything else goes to a worker. Only
    // when the top may have to stay queued (every worker's queue full, or no inline load left this pass) is it
    // peeked at first: with room for it either way it is taken whatever it is (a peek + pop is two more hash
    // lookups per request).
    const bool workers_full = loads_in_flight_ >= workers * kJobsPerWorker;
    const bool inline_left = inline_loads < kInlineMissesPerPass && inline_asked < kInlineMissBytes;
    if (workers_full || !inline_left) {
      const LoadRequest top = *scheduler_.top();
      if (top.page || (!loader_.holds(top.key()) && !cache_.contains(top.key()))) {
        // A local miss that may load inline waits for the next pass's inline loads rather than go to a worker:
        // the hand-off to a worker and back costs more than the read itself (see kInlineMissBytes).
        if (inline_bytes(top) != 0 ? !inline_left : workers_full) break;
      }
    }
    const LoadRequest request = *scheduler_.pop();
    const uint32_t slot = *slots_.acquire();
    any = true;
    if (request.page) {
      // A page is never in the RAM cache: read here when its bytes are local and small, else by a worker.
      if (const uint64_t bytes = inline_left ? inline_bytes(request) : 0; bytes != 0) {
        ++inline_loads;
        inline_asked += bytes;
        // Not charged to a texture in ServerBlock::loading: a page file is no texture of the table.
        const CompletionRecord c = pages_->load(request, slot, segment_.slot(slot), /*local_only=*/true);
        handle_local_result(LoadResult{c, slot, request.received_ns, request});
        continue;
      }
      ++loads_in_flight_;
      workers_->submit(job_of(request, slot));
      continue;
    }
    const scene::TextureRecord& record = textures_[request.texture.value];
    // A level the last inline load brought along is copied from that read's bytes (no cache lookup);
    // otherwise from the cache, where the next request's payload starts loading into the CPU cache while
    // this one is copied.
    const CompletionRecord hit =
        loader_.holds(request.key())
            ? serve_held(request, record, slot)
            : loader_.serve_cached(request, record, slot, segment_.slot(slot), scheduler_.peek_key_hint());
    if (hit.status == static_cast<uint32_t>(CompletionStatus::kOk)) {
      slots_.hand_to_renderer(slot);
      ServerStats::add_one_writer(stats_.hits_ok, 1);
      // Recorded when the completion is published (publish_completions()): one clock read per group.
      hits_unrecorded_.push_back(request.received_ns);
      complete(hit);
      continue;
    }
    if (const uint64_t bytes = inline_left ? inline_bytes(request) : 0; bytes != 0) {
      ++inline_loads;
      inline_asked += bytes;
      load_inline(request, record, slot);
      continue;
    }
    // A miss (or an entry evicted since contains()): the job may wait in the pool's queue for a worker.
    ++loads_in_flight_;
    workers_->submit(LoadJob{request, record, slot});
  }
  // What the pass's last inline load held back goes into the cache now (MipLoader::load's hold_read).
  if (loader_.holding()) loader_.release_held();
  return any;
}

LoadJob Server::job_of(const LoadRequest& request, uint32_t slot) const {
  return LoadJob{request, request.page ? scene::TextureRecord{} : textures_[request.texture.value], slot};
}

CompletionRecord Server::run_job(const LoadJob& job, bool local_only) {
  if (job.request.page) return pages_->load(job.request, job.slot, segment_.slot(job.slot), local_only);
  return loader_.load(job.request, job.record, job.slot, segment_.slot(job.slot), local_only);
}

CompletionRecord Server::serve_held(const LoadRequest& request, const scene::TextureRecord& record, uint32_t slot) {
  const CompletionRecord held = loader_.serve_held(request, record, slot, segment_.slot(slot));
  if (held.status == static_cast<uint32_t>(CompletionStatus::kOk)) return held;
  return loader_.serve_cached(request, record, slot, segment_.slot(slot), scheduler_.peek_key_hint());
}

bool Server::push_completion(const CompletionRecord& c) {
  if (!completions_.try_push_deferred(c)) return false;
  ++unpublished_completions_;
  // Under fault injection every record is published at once, so that kAfterRingPush is where it always was:
  // after one record became visible, before its statistic is counted.
  if (publish_each_completion_ || unpublished_completions_ >= kPublishBatch) publish_completions();
  return true;
}

void Server::publish_completions() {
  if (!hits_unrecorded_.empty()) {
    // A clock read per hit was ~5 % of the dispatcher's time in texstream-bench server's hit phase; the hits
    // of one group become visible together anyway (or, with the ring full, later: then recorded a bit early).
    const uint64_t now = steady_now_ns();
    for (const uint64_t received : hits_unrecorded_) {
      stats_.hit_latency.record_one_writer(now > received ? (now - received) / 1000 : 0);
    }
    hits_unrecorded_.clear();
  }
  if (unpublished_completions_ == 0) return;
  completions_.publish();
  CompletionBell(segment_).ring();          // wakes a renderer thread only if one waits for completions
  fault_point(FaultPoint::kAfterRingPush);  // published, statistics not yet counted
  // relaxed: statistic
  segment_.server_block().completions.v.fetch_add(unpublished_completions_, std::memory_order_relaxed);
  unpublished_completions_ = 0;
}

void Server::complete(const CompletionRecord& c) {
  fault_point(FaultPoint::kBeforeCompletion);  // payload and checksum in the slot, completion not pushed
  // Order is kept: once anything waits locally, later completions queue behind it. The record becomes
  // visible to the renderer at the end of the pass (publish_completions()).
  if (overflow_.empty() && push_completion(c)) return;
  overflow_.push_back(c);
}

bool Server::flush_completions() {
  bool any = false;
  while (!overflow_.empty() && push_completion(overflow_.front())) {
    overflow_.pop_front();
    any = true;
  }
  return any;
}

void Server::idle_wait() {
  // Adaptive spin (docs/design/syscalls.md): while the recent gaps were shorter than kSpinBeforeSleep (a
  // renderer or bench streaming batch after batch), a pause loop without system calls catches the next request
  // and saves the futex sleep and wake; while they were longer (a renderer that asks once per frame), it sleeps
  // at once. A spin on every gap took the core from the renderer on 2 cores (texstream-chaos: IPC per frame
  // p99 80 -> 180 us), and a sched_yield loop was ~35 system calls per gap.
  const auto has_work = [this] {
    return requests_.size() > 0 || workers_->results_ready() || remote_workers_->results_ready();
  };
  constexpr uint64_t kSpinNs = std::chrono::duration_cast<std::chrono::nanoseconds>(kSpinBeforeSleep).count();
  const uint64_t start = steady_now_ns();
  const auto learn = [this, start] {
    // Capped, so that a long idle spell is forgotten within ~5 short gaps once streaming starts again.
    const uint64_t gap = std::min<uint64_t>(steady_now_ns() - start, 4 * kSpinNs);
    idle_gap_ns_ = idle_gap_ns_ - idle_gap_ns_ / 4 + gap / 4;  // moving average over ~4 gaps
  };
  if (idle_gap_ns_ < kSpinNs) {
    for (uint32_t i = 1;; ++i) {
      if (has_work()) {
        learn();
        return;
      }
      if (i % 16 == 0 && steady_now_ns() - start >= kSpinNs) break;
      cpu_relax();
    }
  }
  const auto idle = std::chrono::microseconds(static_cast<int64_t>(config_.idle_wait_ms * 1000.0));
  // Loads in flight or completions waiting for ring space: nap briefly (workers also wake us).
  const bool short_nap = loads_in_flight_ > 0 || !overflow_.empty();
  const auto timeout = short_nap               ? std::min(idle, kBusyWait)
                       : remote_in_flight_ > 0 ? std::min(idle, kRemoteBusyWait)
                                               : idle;
  // The server's half of the doorbell (doorbell.hpp): the ring and the workers' results are re-checked after
  // `sleeping` is published, so neither a push nor a result can slip in unseen.
  Doorbell(segment_).sleep(timeout, has_work);
  learn();
}

}  // namespace texstream::server
