#include "texstream/stream/stream_client.hpp"
#include "stream_client_internal.hpp"

#include <signal.h>
#include <unistd.h>

#include <spdlog/spdlog.h>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <utility>

#include "texstream/common/contract.hpp"
#include "texstream/common/memory_info.hpp"
#include "texstream/common/syscall_count.hpp"
#include "texstream/common/texel_format.hpp"
#include "texstream/protocol/checksum.hpp"
#include "texstream/protocol/liveness.hpp"

namespace texstream::stream {

namespace {

// Protocol errors are logged in full at first, then sampled: a hostile server must not flood the log.
constexpr uint64_t kProtocolErrorsLoggedInFull = 20;
constexpr uint64_t kProtocolErrorLogEvery = 1000;

std::string mip_name(uint32_t texture, uint32_t mip) {
  return "texture " + std::to_string(texture) + " mip " + std::to_string(mip);
}

}  // namespace

// Forwards to the renderer's sink; the time spent there is the renderer's, not IPC.
class StreamClient::TimedSink final : public MipSink {
 public:
  TimedSink(StreamClient& owner, MipSink& inner) : owner_(owner), inner_(inner) {}
  std::span<std::byte> reserve(TextureId texture, MipLevel mip, uint64_t bytes) override {
    const auto t0 = std::chrono::steady_clock::now();
    auto r = inner_.reserve(texture, mip, bytes);
    owner_.sink_ns_ += detail::elapsed_ns(t0);
    return r;
  }
  void commit(TextureId texture, MipLevel mip, std::span<std::byte> data) override {
    const auto t0 = std::chrono::steady_clock::now();
    inner_.commit(texture, mip, data);
    owner_.sink_ns_ += detail::elapsed_ns(t0);
  }
  void reject(TextureId texture, MipLevel mip, std::span<std::byte> reserved) override {
    const auto t0 = std::chrono::steady_clock::now();
    inner_.reject(texture, mip, reserved);
    owner_.sink_ns_ += detail::elapsed_ns(t0);
  }
  void failed(TextureId texture, MipLevel mip, CompletionStatus status) override {
    const auto t0 = std::chrono::steady_clock::now();
    inner_.failed(texture, mip, status);
    owner_.sink_ns_ += detail::elapsed_ns(t0);
  }

 private:
  StreamClient& owner_;
  MipSink& inner_;
};

const char* to_string(RequestOutcome outcome) {
  switch (outcome) {
    case RequestOutcome::kSent:
      return "sent";
    case RequestOutcome::kAlreadyInFlight:
      return "already in flight";
    case RequestOutcome::kInFlightLimit:
      return "in-flight limit reached";
    case RequestOutcome::kRingFull:
      return "request ring full";
    case RequestOutcome::kNoServer:
      return "no server";
    case RequestOutcome::kUnknownTexture:
      return "unknown texture";
    case RequestOutcome::kBadMip:
      return "mip level out of range";
    case RequestOutcome::kQuarantined:
      return "texture quarantined (it crashed the server twice)";
    case RequestOutcome::kUnknownPageFile:
      return "unknown page file";
    case RequestOutcome::kPageNotStored:
      return "page not stored";
    case RequestOutcome::kPageTooLarge:
      return "page larger than a staging slot";
  }
  return "?";
}

SendResult to_send_result(RequestOutcome outcome) {
  switch (outcome) {
    case RequestOutcome::kSent:
    // Answered at once: its kCorrupt comes with the next poll. kSent, so the texture states hold the mip
    // pending and take that failure (kSkip would leave the texture wanted, and asked for, forever).
    case RequestOutcome::kQuarantined:
      return SendResult::kSent;
    case RequestOutcome::kAlreadyInFlight:
    case RequestOutcome::kUnknownTexture:
    case RequestOutcome::kBadMip:
    case RequestOutcome::kUnknownPageFile:
    case RequestOutcome::kPageNotStored:
    case RequestOutcome::kPageTooLarge:
      return SendResult::kSkip;
    case RequestOutcome::kInFlightLimit:
    case RequestOutcome::kRingFull:
    case RequestOutcome::kNoServer:
      return SendResult::kStop;
  }
  return SendResult::kStop;
}

Result<std::unique_ptr<StreamClient>> StreamClient::start(const Config& config, TextureTable shapes,
                                                          const std::filesystem::path& scene_dir,
                                                          const std::filesystem::path& config_file,
                                                          const std::vector<std::string>& overrides,
                                                          StreamClientOptions options) {
  TS_TRY(config.validate());
  std::unique_ptr<StreamClient> c(new StreamClient());
  c->config_ = config;
  c->options_ = std::move(options);
  c->shapes_ = std::move(shapes);

  // The staging slots: protocol.staging_slot_bytes, or (0) sized for the scene's largest mip. A level larger
  // than a slot can never be sent: said once, naming the first such texture, instead of leaving it flat colour
  // without a word (the server refuses each request for it).
  {
    uint64_t largest = 0;
    for (const TextureShape& t : c->shapes_) largest = std::max(largest, mip_bytes(t.format, t.width, t.height, 0));
    // The segment is backed when it is made: auto slots leave half of /dev/shm's free space to others.
    const uint64_t shm_free = free_bytes_at("/dev/shm");
    const StagingShape staging = effective_staging(config.protocol, largest, shm_free);
    if (staging.slot_count < static_cast<uint64_t>(config.protocol.staging_slot_count)) {
      spdlog::info(
          "stream client: {} staging slots of {} bytes (protocol.staging_slot_count {} lowered to keep the "
          "pool within {} MiB and half of /dev/shm's {} MiB free)",
          staging.slot_count, staging.slot_bytes, config.protocol.staging_slot_count, kMaxAutoStagingBytes >> 20,
          shm_free == UINT64_MAX ? 0 : shm_free >> 20);
    }
    c->config_.protocol.staging_slot_count = static_cast<int64_t>(staging.slot_count);
    c->config_.protocol.staging_slot_bytes = static_cast<int64_t>(staging.slot_bytes);
    uint64_t too_large = 0, first = 0, first_bytes = 0;
    for (size_t i = 0; i < c->shapes_.size() && largest > staging.slot_bytes; ++i) {
      const TextureShape& t = c->shapes_[i];
      const uint64_t bytes = mip_bytes(t.format, t.width, t.height, 0);
      if (bytes <= staging.slot_bytes) continue;
      if (too_large++ == 0) first = i, first_bytes = bytes;
    }
    if (too_large) {
      spdlog::warn(
          "stream client: {} textures have levels larger than a staging slot ({} bytes, "
          "protocol.staging_slot_bytes; the first: texture {} of {}, level 0 is {} bytes); those levels are "
          "never loaded: raise the key",
          too_large, staging.slot_bytes, first, (scene_dir / "textures.bin").string(), first_bytes);
    }
  }
  std::filesystem::path executable;
  if (c->options_.spawn_server) {
    auto exe = resolve_server_executable(config);
    if (!exe) return exe.error();
    executable = *exe;
    // The server would refuse it at start (exit 2), and be spawned again and again: said once, here.
    TS_TRY(check_server_memory(c->config_, read_memory_info()));
  }

  // Segments of renderers that died without cleaning up (pid + start time no longer alive).
  if (const int removed = Segment::remove_stale("texstream-"); removed > 0) {
    spdlog::info("removed {} stale shared segment(s) of dead renderers", removed);
  }
  const std::string name =
      config.protocol.segment_name.empty() ? "texstream-" + std::to_string(::getpid()) : config.protocol.segment_name;
  // A chosen name (for a standalone server) left behind by a renderer that was killed would block every
  // later one with "exists"; the sweep above only covers the "texstream-" names.
  if (!config.protocol.segment_name.empty() && Segment::remove_if_stale(name)) {
    spdlog::info("removed the stale shared segment '{}' of a dead renderer", name);
  }
  // config.validate() and the key ranges bound these (powers of two, 1..16384 slots, <= 64 MiB a slot).
  SegmentParams params;
  params.request_capacity = static_cast<uint32_t>(config.protocol.request_ring_capacity);
  params.completion_capacity = static_cast<uint32_t>(config.protocol.completion_ring_capacity);
  params.slot_count = static_cast<uint32_t>(c->config_.protocol.staging_slot_count);
  params.slot_bytes = static_cast<uint64_t>(c->config_.protocol.staging_slot_bytes);
  params.texture_count = c->shapes_.size();
  params.texture_table_fingerprint = kTextureTableSeed;
  for (const TextureShape& t : c->shapes_) {
    params.texture_table_fingerprint = texture_table_step(params.texture_table_fingerprint, t.width, t.height,
                                                          t.mip_count, static_cast<uint32_t>(t.format));
  }
  auto segment = Segment::create(name, params);
  if (!segment) return segment.error();
  c->segment_ = std::move(*segment);
  c->slot_held_.assign(c->segment_->slot_count(), 0);
  c->release_pos_.assign(c->segment_->slot_count(), kNoPosition);
  // Loads never take the last records of the request ring: those are for slot releases, so a ring filled
  // with loads cannot keep the server from getting its slots back.
  c->release_reserve_ = std::min<uint32_t>(c->segment_->slot_count(), c->segment_->header().request_capacity / 4);
  c->attach_rings();
  c->quarantine_ = CrashQuarantine(c->shapes_.size());

  std::unique_ptr<ServerProcess> process;
  if (c->options_.spawn_server) {
    ServerCommand cmd{executable, name, scene_dir, config_file, overrides};
    process = std::make_unique<ServerProcess>(std::move(cmd), c->options_.restart);
  }
  const auto heartbeat_timeout = std::chrono::milliseconds(static_cast<int64_t>(config.protocol.heartbeat_timeout_ms));
  c->supervisor_ = std::make_unique<ServerSupervisor>(*c->segment_, std::move(process), heartbeat_timeout);
  c->supervisor_->start(c->now());
  spdlog::info("stream client: segment '{}' ({} slots x {} bytes), {} textures, server {}", name,
               c->segment_->slot_count(), c->segment_->slot_bytes(), c->shapes_.size(),
               c->options_.spawn_server ? executable.string() : std::string("external"));
  return c;
}

StreamClient::~StreamClient() {
  if (frame_open_) ipc_time_.add(frame_ipc_ns_);
  frame_open_ = false;
  // A diagnostic hook for texstream-chaos (tools/chaos): the renderer's summary.json does not carry these.
  if (const char* file = std::getenv("TEXSTREAM_STREAM_STATS"); file && *file) {
    std::ofstream out(file, std::ios::trunc);
    out << stats_text();
    if (!out) spdlog::warn("could not write stream statistics to '{}' ($TEXSTREAM_STREAM_STATS)", file);
  }
  supervisor_.reset();  // kill and reap the server before the segment (and its name) goes away
  segment_.reset();
}

SteadyTime StreamClient::now() const { return options_.clock ? options_.clock() : std::chrono::steady_clock::now(); }

void StreamClient::attach_rings() { endpoint_ = RendererEndpoint(*segment_); }

void StreamClient::begin_cycle() {
  IpcScope scope(*this);
  generation_ = Generation(generation_.value + 1);
  // release: a server that sees this generation also sees the requests pushed before it (ring release).
  segment_->renderer_block().generation.v.store(generation_.value, std::memory_order_release);
}

std::optional<uint64_t> StreamClient::server_read_position() const { return endpoint_.server_read_position(); }

bool StreamClient::slot_in_transit(uint32_t slot) {
  if (release_pos_[slot] == kNoPosition) return false;
  const std::optional<uint64_t> read = server_read_position();
  if (read && *read > release_pos_[slot]) {
    release_pos_[slot] = kNoPosition;  // the server has read our release: the slot is its own again
    return false;
  }
  return true;
}

RequestOutcome StreamClient::try_request(TextureId texture, MipLevel mip, float priority) {
  IpcScope scope(*this);
  if (texture.value >= shapes_.size()) return RequestOutcome::kUnknownTexture;
  if (mip.value >= shapes_[texture.value].mip_count) return RequestOutcome::kBadMip;
  if (quarantine_.quarantined(texture)) {
    // Never sent: the texture states learn at the next poll that it failed for good (kCorrupt).
    quarantine_.refuse(texture, mip);
    return RequestOutcome::kQuarantined;
  }
  if (!supervisor_->accepting_requests()) return RequestOutcome::kNoServer;
  if (in_flight_.count(key(texture, mip))) return RequestOutcome::kAlreadyInFlight;
  if (requests_in_flight() >= static_cast<size_t>(config_.stream.max_requests_in_flight)) {
    return RequestOutcome::kInFlightLimit;
  }
  flush_releases();  // queued releases go first: the server waits for its slots
  if (endpoint_.request_free_space() <= release_reserve_) return RequestOutcome::kRingFull;
  // A ring error: poll() restarts the server.
  if (!endpoint_.push_load(texture, mip, generation_, priority)) return RequestOutcome::kRingFull;
  in_flight_.emplace(key(texture, mip), InFlight{generation_, now()});
  ++stats_.requests_sent;
  if (auto it = lost_.find(key(texture, mip)); it != lost_.end() && !it->second.resent) {
    it->second.resent = true;
    it->second.resent_at = now();
    ++stats_.lost_resent;
  }
  endpoint_.ring();
  return RequestOutcome::kSent;
}

TextureStates::Sender StreamClient::sender() {
  return [this](const MipRequest& r) { return to_send_result(try_request(r.texture, r.mip, r.priority)); };
}

void StreamClient::release_slot(SlotIndex slot) {
  TS_ASSERT(slot.value < slot_held_.size() && slot_held_[slot.value], "releasing slot %u that we do not hold",
            slot.value);
  endpoint_.release(slot);
  flush_releases();
}

void StreamClient::flush_releases() {
  // Full (or a ring error, handled by poll): the rest wait for the next call.
  stats_.releases_sent += endpoint_.flush_releases(generation_, [this](SlotIndex slot, uint64_t position) {
    slot_held_[slot.value] = 0;  // the server owns it once it has read the record
    release_pos_[slot.value] = position;
  });
  endpoint_.ring();
}

void StreamClient::protocol_error(const std::string& what) {
  ++stats_.protocol_errors;
  const uint64_t n = stats_.protocol_errors;
  if (n <= kProtocolErrorsLoggedInFull || n % kProtocolErrorLogEvery == 0) {
    spdlog::warn("texstream-server broke the protocol (error #{}): {}", n, what);
  }
}

void StreamClient::on_server_gone(MipSink& sink, const std::string& why) {
  // Keep the dead server's statistics: the reset zeroes its block.
  const ServerBlock& sb = segment_->server_block();
  past_hits_ += sb.ram_cache_hits.v.load(std::memory_order_relaxed);
  past_misses_ += sb.ram_cache_misses.v.load(std::memory_order_relaxed);
  past_bytes_read_ += sb.bytes_read.v.load(std::memory_order_relaxed);
  past_cancelled_ += sb.requests_cancelled.v.load(std::memory_order_relaxed);
  past_syscalls_ += sb.syscalls.v.load(std::memory_order_relaxed);

  // Everything in flight is lost; the state machine asks again (kCancelled is retried, never counted).
  std::vector<uint64_t> lost;
  lost.reserve(in_flight_.size());
  for (const auto& [k, f] : in_flight_) lost.push_back(k);
  std::sort(lost.begin(), lost.end());  // deterministic order for the sink
  // Recovery accounting: a request sent again and lost again is overdue if its deadline already passed
  // (the server it went to lived long enough to answer it); otherwise it waits for the next server.
  const SteadyTime t = now();
  for (auto& [k, l] : lost_) {
    if (l.resent && t - l.resent_at > kRecoveryDeadline) ++stats_.unserved_after_restart;
    l.resent = false;
  }
  for (uint64_t k : lost) lost_[k] = Lost{};
  in_flight_.clear();
  const std::vector<PageRequest> lost_pages = pages_.take_all();
  held_.reset();
  endpoint_.drop_releases();
  std::fill(slot_held_.begin(), slot_held_.end(), 0);  // the next server owns every slot
  std::fill(release_pos_.begin(), release_pos_.end(), kNoPosition);
  stats_.requests_lost += lost.size() + lost_pages.size();
  if (!lost.empty() || !lost_pages.empty() || !why.empty()) {
    spdlog::warn("texstream-server gone ({}): {} request(s) in flight lost", why, lost.size() + lost_pages.size());
  }
  for (const PageRequest& r : lost_pages) fail_page(r, CompletionStatus::kCancelled);  // asked again if wanted
  for (uint64_t k : lost) {
    const auto texture = static_cast<uint32_t>(k >> 32);
    // A quarantined texture's lost request is its final answer; any other is asked again (kCancelled).
    sink.failed(TextureId(texture), MipLevel(static_cast<uint32_t>(k)),
                quarantine_.quarantined(texture) ? CompletionStatus::kCorrupt : CompletionStatus::kCancelled);
  }
}

// What the supervisor asks of this client, with the sink of the current call.
class StreamClient::SupervisorHooks final : public ServerSupervisor::Client {
 public:
  SupervisorHooks(StreamClient& owner, MipSink& sink) : owner_(owner), sink_(sink) {}
  void server_gone(const ServerSupervisor::Death& death) override {
    // The quarantine first (a quarantined texture's lost requests fail for good), and before the reset
    // (which zeroes the words).
    const ServerBlock& sb = std::as_const(*owner_.segment_).server_block();
    if (owner_.quarantine_.charge_crash(death.crash_signal, sb)) ++owner_.stats_.crash_signal_deaths;
    if (death.hung) owner_.quarantine_.charge_hang(sb);
    owner_.on_server_gone(sink_, death.why);
    if (!death.reset) return;
    owner_.segment_->reset_after_server_death();
    owner_.attach_rings();
  }
  void protocol_error(const std::string& what) override { owner_.protocol_error(what); }

 private:
  StreamClient& owner_;
  MipSink& sink_;
};

void StreamClient::supervise(MipSink& sink) {
  const bool ring_broken = endpoint_.ring_broken() || !server_read_position().has_value();
  expire_requests(sink, now());
  SupervisorHooks hooks(*this, sink);
  supervisor_->supervise(now(), ring_broken, requests_in_flight() != 0, hooks);
}

void StreamClient::wait_for_completions(std::chrono::microseconds timeout) {
  // No server attached: nobody rings the bell, and the wait is the plain sleep it replaced.
  endpoint_.wait_for_completions(timeout);
}

void StreamClient::poll(MipSink& renderer_sink, size_t max_mips) {
  // A poll starts the next frame's IPC sample (requests sent after it count with it).
  if (frame_open_) ipc_time_.add(frame_ipc_ns_);
  frame_ipc_ns_ = 0;
  frame_open_ = true;
  IpcScope scope(*this);
  TimedSink sink(*this, renderer_sink);
  RendererBlock& rb = segment_->renderer_block();
  // relaxed: a progress counter only; we are its sole writer.
  rb.heartbeat.v.store(rb.heartbeat.v.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  supervise(sink);
  quarantine_.fail_refused(sink);
  if (!supervisor_->accepting_requests()) return;
  flush_releases();

  size_t mips = 0;
  if (held_) {
    if (mips >= max_mips) return;
    const CheckedCompletion c = *held_;
    held_.reset();
    // Still no room: keep order, try again next poll.
    if (!(c.kind == RequestKind::kLoadPage ? deliver_page(c) : deliver(c, sink))) return;
    ++mips;
  }
  // Bounded by one ring's worth per poll: a server publishing as fast as we consume cannot hold us here.
  const uint32_t max_records = segment_->header().completion_capacity;
  for (uint32_t n = 0; n < max_records && mips < max_mips && !held_; ++n) {
    const std::optional<CompletionRecord> record = endpoint_.poll();
    if (!record) break;
    handle_record(*record, sink, mips);
  }
  if (endpoint_.completions_broken()) supervise(sink);  // act on a corrupt position this frame
}

void StreamClient::handle_record(const CompletionRecord& record, MipSink& sink, size_t& mips) {
  const uint32_t slot_count = segment_->slot_count();
  auto checked = check_completion(record, slot_count, segment_->slot_bytes());
  if (!checked) {
    protocol_error(checked.error().message + " (" + mip_name(record.texture_id, record.mip_level) + ")");
    // A server that believes it handed us a slot gets it back, once; a slot we already hold is not
    // released again (that would give the server a slot twice).
    if (record.status == static_cast<uint32_t>(CompletionStatus::kOk) && record.slot < slot_count &&
        !slot_held_[record.slot] && !slot_in_transit(record.slot)) {
      slot_held_[record.slot] = 1;
      release_slot(SlotIndex(record.slot));
    }
    // A request it claims to answer is answered badly: ask again later. A record whose kind is garbage may
    // name a page as well as a mip (a hostile server can fail any request anyway, with a failure status).
    if (record.request_kind != static_cast<uint32_t>(RequestKind::kLoad)) {
      const PageRequest r{record.texture_id, pages::PageId{record.mip_level, record.page_x, record.page_y}};
      if (pages_.find(r) != nullptr) {
        pages_.erase(r);
        ++stats_.completions_rejected;
        fail_page(r, CompletionStatus::kIoError);
        return;
      }
      if (record.request_kind == static_cast<uint32_t>(RequestKind::kLoadPage)) return;
    }
    if (auto it = in_flight_.find(key(TextureId(record.texture_id), MipLevel(record.mip_level)));
        it != in_flight_.end()) {
      in_flight_.erase(it);
      note_answered(key(TextureId(record.texture_id), MipLevel(record.mip_level)));
      ++stats_.completions_rejected;
      sink.reject(TextureId(record.texture_id), MipLevel(record.mip_level), {});
    }
    return;
  }
  const CheckedCompletion& c = *checked;
  if (c.kind == RequestKind::kLoadPage) {
    handle_page_record(c, mips);
    return;
  }
  const bool ok = c.status == CompletionStatus::kOk;
  const auto in_flight = in_flight_.find(key(c.texture, c.mip));
  const bool asked = in_flight != in_flight_.end();

  auto refuse = [&](const std::string& what, bool release) {
    protocol_error(what + " (" + mip_name(c.texture.value, c.mip.value) + ")");
    if (ok && release) release_slot(c.slot);
    if (asked) {
      in_flight_.erase(in_flight);
      note_answered(key(c.texture, c.mip));
      ++stats_.completions_rejected;
      sink.reject(c.texture, c.mip, {});
    }
  };

  if (std::string why; ok && !take_slot(c.slot, why)) {
    refuse(why, false);
    return;
  }
  if (c.texture.value >= shapes_.size()) {
    refuse("texture id outside the table of " + std::to_string(shapes_.size()), true);
    return;
  }
  if (!asked) {
    refuse("an answer to a request we did not send (or already answered)", true);
    return;
  }
  if (c.generation != in_flight->second.generation) {
    refuse("generation " + std::to_string(c.generation.value) + " but the request had " +
               std::to_string(in_flight->second.generation.value),
           true);
    return;
  }
  if (!ok) {
    in_flight_.erase(in_flight);
    note_answered(key(c.texture, c.mip));
    ++stats_.completions_failed[static_cast<uint32_t>(c.status)];
    sink.failed(c.texture, c.mip, c.status);
    return;
  }
  if (auto st = check_against_texture(c, shapes_[c.texture.value]); !st.ok()) {
    refuse(st.error().message, true);
    return;
  }
  if (deliver(c, sink)) ++mips;
}

bool StreamClient::take_slot(SlotIndex slot, std::string& why) {
  if (slot_held_[slot.value]) {
    why = "slot " + std::to_string(slot.value) + " handed over while we still hold it";
    return false;
  }
  // If the server's read position has not passed our release record even now, it had certainly not read
  // it when it published this completion: it handed over a slot it did not own.
  if (slot_in_transit(slot.value)) {
    why = "slot " + std::to_string(slot.value) + " handed over before the server read its release";
    return false;
  }
  slot_held_[slot.value] = 1;  // the ring has handed it to us
  return true;
}

bool StreamClient::deliver(const CheckedCompletion& c, MipSink& sink) {
  std::span<std::byte> dst = sink.reserve(c.texture, c.mip, c.byte_size);
  if (dst.empty()) {
    held_ = c;  // the slot stays ours and the request stays in flight until there is room
    return false;
  }
  TS_ASSERT(dst.size() >= c.byte_size, "MipSink::reserve gave %zu bytes for a %llu-byte mip", dst.size(),
            static_cast<unsigned long long>(c.byte_size));
  // check_completion bounded slot < slot_count and byte_size <= slot_bytes: the read stays in the slot.
  const std::span<std::byte> src = segment_->slot(c.slot.value);
  std::memcpy(dst.data(), src.data(), c.byte_size);  // read the shared bytes once
  in_flight_.erase(key(c.texture, c.mip));
  note_answered(key(c.texture, c.mip));
  const std::span<std::byte> payload = dst.first(c.byte_size);
  // The checksum is computed on our copy: the server may change the slot after we read it.
  if (payload_checksum(payload.data(), payload.size()) == c.checksum) {
    ++stats_.completions_ok;
    stats_.bytes_received += c.byte_size;
    sink.commit(c.texture, c.mip, payload);
  } else {
    protocol_error("payload checksum mismatch (" + mip_name(c.texture.value, c.mip.value) + ")");
    ++stats_.completions_rejected;
    ++stats_.payload_checksum_failures;
    sink.reject(c.texture, c.mip, dst);
  }
  release_slot(c.slot);
  return true;
}

void StreamClient::restart_server(const std::string& why, MipSink& renderer_sink) {
  IpcScope scope(*this);
  TimedSink sink(*this, renderer_sink);
  SupervisorHooks hooks(*this, sink);
  supervisor_->restart(why, hooks);
}

void StreamClient::expire_requests(MipSink& sink, SteadyTime t) {
  // A scan at most every 1/8 of the timeout: the map may hold thousands of requests.
  if (requests_in_flight() == 0 || t < next_expiry_scan_) return;
  next_expiry_scan_ = t + options_.request_timeout / 8;
  std::vector<PageRequest> expired_pages = pages_.take_expired(t, options_.request_timeout);
  if (held_ && held_->kind == RequestKind::kLoadPage) {
    const PageRequest h{held_->page_file, held_->page};
    if (std::erase(expired_pages, h) != 0) {
      pages_.sent(h, held_->generation, t);  // answered; only the sink had no room: it stays in flight
    }
  }
  for (const PageRequest& r : expired_pages) {
    ++stats_.requests_timed_out;
    fail_page(r, CompletionStatus::kTimedOut);
  }
  std::vector<uint64_t> expired;
  for (const auto& [k, f] : in_flight_)
    if (t - f.sent_at > options_.request_timeout) expired.push_back(k);
  std::sort(expired.begin(), expired.end());  // deterministic order for the sink
  if (held_ && held_->kind == RequestKind::kLoad &&
      std::binary_search(expired.begin(), expired.end(), key(held_->texture, held_->mip))) {
    std::erase(expired, key(held_->texture, held_->mip));  // answered; only the sink had no room
  }
  if (expired.empty() && expired_pages.empty()) return;
  for (uint64_t k : expired) {
    in_flight_.erase(k);
    note_answered(k);
    ++stats_.requests_timed_out;
    sink.failed(TextureId(static_cast<uint32_t>(k >> 32)), MipLevel(static_cast<uint32_t>(k)),
                CompletionStatus::kTimedOut);
  }
  const std::string what = std::to_string(expired.size() + expired_pages.size()) + " request(s) unanswered for " +
                           std::to_string(options_.request_timeout.count()) + " ms: failed as timed out";
  // With no server attached nobody broke the protocol: nobody was there to answer (server.spawn = false and no
  // standalone server yet, or a spawned one that has not attached). Before, each expiry counted as a protocol
  // error of a server that did not exist.
  if (const std::string unattached = supervisor_->unattached_reason(); !unattached.empty()) {
    spdlog::warn("{} ({})", what, unattached);
    return;
  }
  protocol_error(what);
}

void StreamClient::note_answered(uint64_t k) {
  const auto it = lost_.find(k);
  if (it == lost_.end() || !it->second.resent) return;
  if (now() - it->second.resent_at <= kRecoveryDeadline) {
    ++stats_.lost_answered_in_time;
  } else {
    ++stats_.unserved_after_restart;
  }
  lost_.erase(it);
}

uint64_t StreamClient::overdue_lost(SteadyTime t) const {
  return static_cast<uint64_t>(std::count_if(lost_.begin(), lost_.end(), [&](const auto& e) {
    return e.second.resent && t - e.second.resent_at > kRecoveryDeadline;
  }));
}

bool StreamClient::in_flight(TextureId texture, MipLevel mip) const { return in_flight_.count(key(texture, mip)) != 0; }

StreamStats StreamClient::stats() const {
  StreamStats s = stats_;
  s.in_flight = requests_in_flight();
  s.slots_held = static_cast<uint64_t>(std::count(slot_held_.begin(), slot_held_.end(), uint8_t{1}));
  s.releases_queued = endpoint_.releases_queued();
  const ServerBlock& sb = std::as_const(*segment_).server_block();
  s.server_ram_cache_hits = past_hits_ + sb.ram_cache_hits.v.load(std::memory_order_relaxed);
  s.server_ram_cache_misses = past_misses_ + sb.ram_cache_misses.v.load(std::memory_order_relaxed);
  s.server_bytes_read = past_bytes_read_ + sb.bytes_read.v.load(std::memory_order_relaxed);
  s.server_requests_cancelled = past_cancelled_ + sb.requests_cancelled.v.load(std::memory_order_relaxed);
  s.server_syscalls = past_syscalls_ + sb.syscalls.v.load(std::memory_order_relaxed);
  s.syscalls = process_syscalls().total();
  s.unserved_after_restart += overdue_lost(now());
  s.server_deaths = supervisor_->server_deaths();
  s.server_deaths_before_attach = supervisor_->server_deaths_before_attach();
  s.server_refusals_before_attach = supervisor_->server_refusals_before_attach();
  s.standalone_refused_by = supervisor_->standalone_refused_by();
  s.textures_quarantined = quarantine_.textures_quarantined();
  if (const ServerProcess* process = supervisor_->process()) {
    s.server_crashes = supervisor_->server_crashes();
    s.server_restarts = supervisor_->server_restarts();
    switch (process->state()) {
      case ServerState::kStopped:
      case ServerState::kBackingOff:
        s.server_state = StreamServerState::kBackingOff;
        break;
      case ServerState::kRunning:
        s.server_state = StreamServerState::kRunning;
        break;
      case ServerState::kColormapOnly:
        s.server_state = StreamServerState::kColormapOnly;
        break;
    }
  } else {
    s.server_state = supervisor_->broken() ? StreamServerState::kBroken : StreamServerState::kExternal;
  }
  return s;
}

std::string StreamClient::stats_text() const { return format_stream_stats(stats(), ipc_time_); }

}  // namespace texstream::stream
