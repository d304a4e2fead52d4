// How completions come into the frame loop and how a streaming cycle starts (renderer.hpp): real time (at
// most controller.load_time_ms a frame), lock-step (every answer to the previous cycle, in texture order),
// whole mip chains (render.preload_all, render.blocking_loads) and each frame's wanted levels before it is
// drawn (render.load_wanted_before_drawing).
#include <spdlog/spdlog.h>

#include <algorithm>
#include <limits>
#include <numbers>
#include <thread>

#include "renderer.hpp"
#include "texstream/render/cache/completion_sinks.hpp"
#include "texstream/render/frame/visibility_list.hpp"

namespace texstream::render {

namespace {

// Lock-step (DESIGN "Determinism and measurement"): the longest a frame waits for the server to answer the
// previous cycle before the run is declared stuck. Generous: a cold server on a loaded 2-core machine.
constexpr std::chrono::seconds kLockstepTimeout{60};

// load_fully(): this many rounds in a row that send requests but publish no mip end the load with an error
// instead of spinning (a server that answers everything with retryable failures, a cache that evicts what it
// just loaded). A healthy round publishes at least one mip; 64 rounds is far beyond any retry burst.
constexpr uint32_t kMaxFruitlessLoadRounds = 64;

}  // namespace

void Renderer::tell_states() {
  const std::vector<stream::TextureEvent> events = stack_->cache().take_events();
  states_->apply(events);
  mip_use_->apply(events);
}

Result<Renderer::Clock::duration> Renderer::take_completions() {
  TextureCache& cache = stack_->cache();
  if (!cfg_.render.lockstep) {
    LoadTimeSink timed(cache,
                       Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                          std::chrono::duration<double, std::milli>(cfg_.controller.load_time_ms)));
    // Mode auto paces a frame's intake by the measured cost of a mip (headroom_controller.hpp, "pace").
    const double pace = std::floor(controller_->pace_mips());
    const auto limit = static_cast<size_t>(std::min(static_cast<double>(cfg_.stream.max_mips_per_cycle), pace));
    client_->poll(timed, limit);
    if (timed.limited()) record_.count_load_time_limited();
    TS_TRY(server_not_refusing(kMaxDeathsBeforeAttach));
    return Clock::duration{0};
  }
  // Lock-step: the frame first takes every answer to the previous cycle (or as many as the staging ring
  // holds), so what it shows depends on the frame index only, not on timing.
  const auto wait_start = Clock::now();
  OrderedCommitSink ordered(cache);
  LoadTimeSink all(ordered, Clock::time_point::max());
  while (client_->stats().in_flight > 0) {
    client_->poll(all, std::numeric_limits<size_t>::max());
    if (all.no_room() || client_->stats().in_flight == 0) break;
    if (Clock::now() - wait_start > kLockstepTimeout) {
      return make_error(ErrorCode::kTimeout, "render.lockstep: " + std::to_string(client_->stats().in_flight) +
                                                 " requests still unanswered after " +
                                                 std::to_string(kLockstepTimeout.count()) + " s");
    }
    client_->wait_for_completions(std::chrono::microseconds(200));
  }
  ordered.flush();  // the whole frame's arrivals, in (texture, mip) order
  const Clock::duration waited = Clock::now() - wait_start;
  // A server that died took its requests along: what the next frames show would depend on when it came
  // back, which is what lock-step promises to rule out (and a server that cannot start would leave a run of
  // colormap frames that reports success).
  if (client_->stats().server_deaths != deaths_before_frames_) {
    return make_error(ErrorCode::kPeerDead, "render.lockstep: texstream-server died during the run (" +
                                                client_->last_server_exit() +
                                                "); its frames would depend on when it came back");
  }
  return waited;
}

std::vector<stream::StreamCandidate> Renderer::read_candidates() {
  uint64_t skipped = 0;
  const auto candidates = build_candidates(stack_->scene_gpu().read_back_entries(), scene_.mesh_records().size(),
                                           scene_.texture_records().size(), &skipped);
  if (skipped) spdlog::warn("visibility list: {} entries with a bad mesh id skipped", skipped);
  stack_->cache().touch(candidates);  // what this cycle shows is not evicted (cache.eviction = lru)
  return candidates;
}

void Renderer::start_cycle(const std::vector<stream::StreamCandidate>& candidates, const std::function<void()>& first) {
  tell_states();
  client_->begin_cycle();
  ++cycles_;
  if (first) first();
  // stream.max_mips_per_cycle caps the requests of one cycle on top of the load size s.
  uint64_t sent = 0;
  const auto max_mips = static_cast<uint64_t>(cfg_.stream.max_mips_per_cycle);
  auto send = client_->sender();
  // Algorithm 1: the cycle stops at load size s and refines a texture only while desired + b < resident.
  load_bytes_ = controller_->load_bytes();
  const auto bias = static_cast<float>(controller_->mip_bias());
  const auto result = states_->run_cycle(candidates, load_bytes_, bias, [&](const stream::MipRequest& r) {
    if (sent >= max_mips) return stream::SendResult::kStop;
    const stream::SendResult s = send(r);
    if (s == stream::SendResult::kSent) ++sent;
    return s;
  });
  last_cycle_sent_ = result.sent.size();
  spdlog::debug("cycle {}: {} candidates, {} requests, {} bytes", cycles_, candidates.size(), result.sent.size(),
                result.bytes);
}

void Renderer::request_ground_pages(uint64_t frame, const CameraPose& pose) {
  GroundPages* ground = stack_->ground();
  if (!ground) return;
  // HotSpot's centre moves to the side the camera turns towards (right and down positive), beyond half a degree
  // 0.01 rad per frame (seed 004 §4.2; texstream-bench pages uses the same threshold). Yaw grows to the right.
  pages::HotSpot hotspot;
  if (last_pose_) {
    const double yaw = (pose.yaw_deg - last_pose_->yaw_deg) * std::numbers::pi / 180.0;
    const double pitch = (last_pose_->pitch_deg - pose.pitch_deg) * std::numbers::pi / 180.0;
    hotspot = pages::hotspot_from_turn(static_cast<float>(yaw), static_cast<float>(pitch), 0.01f);
  }
  // Pages go ahead of the cycle's mips at the server: the per-frame budget (pages.per_frame) bounds them, and
  // the ground is under every view.
  const auto candidates = ground->plan(frame, hotspot);
  for (size_t i = 0; i < candidates.size(); ++i) {
    const float priority = std::numeric_limits<float>::max() / 2 - static_cast<float>(i);
    const stream::RequestOutcome o = client_->try_request_page(GroundPages::kFileId, candidates[i].page, priority);
    if (o == stream::RequestOutcome::kSent) {
      ground->on_requested(candidates[i].page);
    } else if (stream::to_send_result(o) == stream::SendResult::kStop) {
      break;
    }
  }
}

Status Renderer::load_ground_wanted(uint64_t index, bool whole) {
  GroundPages* ground = stack_->ground();
  if (!ground) return ok_status();
  // Every page the probe frame's needbuffer wants, with their ancestors (pages.order), or every stored page
  // (`whole`: render.preload_all), round after round until none is missing: staging holds staging_pages at once,
  // so a full staging buffer is uploaded in between.
  LoadTimeSink none(stack_->cache(), Clock::time_point::max());
  for (uint32_t round = 0; round < kMaxFruitlessLoadRounds; ++round) {
    const auto wanted = whole ? ground->missing_pages() : ground->plan(index, {}, true);
    if (wanted.empty()) return ok_status();
    for (const pages::PageCandidate& c : wanted) {
      const stream::RequestOutcome o = client_->try_request_page(GroundPages::kFileId, c.page, 1.0f);
      if (o == stream::RequestOutcome::kSent) ground->on_requested(c.page);
      if (stream::to_send_result(o) == stream::SendResult::kStop) break;
    }
    const auto start = Clock::now();
    while (ground->pending() > 0) {
      client_->poll(none, std::numeric_limits<size_t>::max());
      TS_TRY(server_can_start());
      if (ground->staging_full()) TS_TRY(upload_now());
      if (Clock::now() - start > kLockstepTimeout) {
        return make_error(ErrorCode::kTimeout, "frame " + std::to_string(index) + ": " +
                                                   std::to_string(ground->pending()) +
                                                   " ground pages unanswered while loading the wanted ones");
      }
      if (ground->pending() > 0) client_->wait_for_completions(std::chrono::microseconds(200));
    }
    TS_TRY(upload_now());
  }
  return make_error(ErrorCode::kTimeout, "frame " + std::to_string(index) +
                                             ": the ground's wanted pages did not "
                                             "all arrive in " +
                                             std::to_string(kMaxFruitlessLoadRounds) +
                                             " rounds (do they fit pages.memory_bytes?)");
}

Status Renderer::upload_now() {
  Submission s;
  s.uploads = Uploads::kMips;
  return stack_->submit(s);
}

Status Renderer::load_fully(std::vector<stream::StreamCandidate> wanted, LoadGoal goal) {
  TextureCache& cache = stack_->cache();
  // No bias, and desired level 0 for whole chains: Algorithm 1 then refines each texture one level per round,
  // coarsest first, until its base level is resident (Final), or until resident <= desired (Algorithm 1's
  // own stop: floor(desired) when the chain reaches it). Each round waits for every answer before the next,
  // so the state machine sees the previous level published first.
  const bool to_wanted = goal == LoadGoal::kWantedLevels;
  if (!to_wanted) {
    for (stream::StreamCandidate& c : wanted) c.desired_mip = 0.0f;
  }
  const uint64_t evictions_before = cache.stats().evictions;
  // What is placed from here on is `wanted` only (kWantedLevels' fit check).
  const TextureCache::FitMark fit = cache.fit_mark();
  uint32_t fruitless = 0;
  auto idle_since = Clock::now();
  for (;;) {
    const uint64_t published_before = cache.stats().mips_uploaded;
    tell_states();
    client_->begin_cycle();
    ++cycles_;
    // A round asks for at most half the staging ring, so all its answers are held and committed at once
    // (in texture order) below: which answers share a poll is timing, and must not decide cache regions.
    const uint64_t round_cap = static_cast<uint64_t>(cfg_.render.staging_bytes) / 2;
    uint64_t round_bytes = 0;
    auto client_send = client_->sender();
    auto send = [&](const stream::MipRequest& r) {
      if (round_bytes > 0 && round_bytes + r.bytes > round_cap) return stream::SendResult::kStop;
      const stream::SendResult sr = client_send(r);
      if (sr == stream::SendResult::kSent) round_bytes += r.bytes;
      return sr;
    };
    const auto result = states_->run_cycle(wanted, std::numeric_limits<uint64_t>::max(), 0.0f, send,
                                           static_cast<size_t>(cfg_.stream.max_mips_per_cycle));
    if (result.sent.empty() && client_->stats().in_flight == 0) {
      // Nothing to send: either every wanted texture is complete (or broken), or the server takes no
      // requests right now (starting, restarting after a crash): then wait for it, within the timeout.
      const auto incomplete = std::count_if(wanted.begin(), wanted.end(), [&](const stream::StreamCandidate& c) {
        const stream::TextureStateView v = states_->view(c.texture);
        // As next_mip's test: a NaN desired level asks for nothing.
        return !v.broken && (!v.resident || c.desired_mip < static_cast<float>(*v.resident));
      });
      if (incomplete == 0) return ok_status();
      if (Clock::now() - idle_since > kLockstepTimeout) {
        const std::string unattached = client_->unattached_reason();
        return make_error(ErrorCode::kTimeout, std::to_string(incomplete) +
                                                   " textures still incomplete and the server takes no requests (" +
                                                   to_string(client_->stats().server_state) + ") after " +
                                                   std::to_string(kLockstepTimeout.count()) + " s" +
                                                   (unattached.empty() ? "" : ": " + unattached));
      }
      client_->poll(cache, 0);  // supervision: reap, restart
      TS_TRY(server_can_start());
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      continue;
    }
    idle_since = Clock::now();
    auto last_progress = Clock::now();
    uint64_t answered = client_->stats().completions_ok;
    OrderedCommitSink ordered(cache);  // arrival order must not decide cache regions (reruns identical)
    while (client_->stats().in_flight > 0) {
      LoadTimeSink all(ordered, Clock::time_point::max());
      client_->poll(all, std::numeric_limits<size_t>::max());
      TS_TRY(server_can_start());
      if (all.no_room()) {  // only if one mip is above half the ring: upload to free it
        ordered.flush();
        TS_TRY(upload_now());
      }
      if (client_->stats().completions_ok != answered) {
        answered = client_->stats().completions_ok;
        last_progress = Clock::now();
      } else if (Clock::now() - last_progress > kLockstepTimeout) {
        return make_error(ErrorCode::kTimeout, std::to_string(client_->stats().in_flight) +
                                                   " requests unanswered for " +
                                                   std::to_string(kLockstepTimeout.count()) +
                                                   " s while loading "
                                                   "whole mip chains");
      } else if (client_->stats().in_flight > 0) {
        client_->wait_for_completions(std::chrono::microseconds(200));
      }
    }
    ordered.flush();
    TS_TRY(upload_now());
    if (to_wanted) {
      // ring: layers go in the order they were assigned, so once one assigned during this load is freed, every
      // live layer holds textures of `wanted` only and they still did not fit; lru: a copy was refused because
      // everything that could go was wanted (docs/design/reference_frames.md). Evictions of textures not wanted
      // are fine.
      if (cache.outgrown_since(fit)) {
        return make_error(
            ErrorCode::kResourceExhausted,
            "render.load_wanted_before_drawing: the " + std::to_string(wanted.size()) +
                " textures this frame samples do not fit the texture cache at their wanted levels; "
                "raise cache.memory_bytes (now " +
                std::to_string(cfg_.cache.memory_bytes) + ")" +
                (cache.eviction() == CacheEviction::kRing ? " or cache.layers (now " + std::to_string(cache.layers()) +
                                                                " of " + std::to_string(cache.layer_extent()) + " px)"
                                                          : ""));
      }
    } else if (cache.stats().evictions != evictions_before || cache.outgrown_since(fit)) {
      if (goal == LoadGoal::kWholeScene) {
        return make_error(ErrorCode::kResourceExhausted,
                          "render.preload_all: the cache evicted textures while loading the whole scene; raise "
                          "cache.memory_bytes (now " +
                              std::to_string(cfg_.cache.memory_bytes) + ") and cache.layers (now " +
                              std::to_string(cfg_.cache.layers) + ")");
      }
      return ok_status();  // the visible set does not fit: draw with what is resident
    }
    fruitless = cache.stats().mips_uploaded == published_before ? fruitless + 1 : 0;
    if (fruitless >= kMaxFruitlessLoadRounds) {
      return make_error(ErrorCode::kTimeout, std::to_string(kMaxFruitlessLoadRounds) +
                                                 " load rounds in a row published no mip (" +
                                                 std::to_string(result.sent.size()) + " requests in the last)");
    }
  }
}

Status Renderer::load_wanted(const FrameRecording& rec, uint64_t index) {
  // The frame as it will be drawn, with feedback: the main pass only (meshes entirely outside the viewport are
  // not drawn in the frame that counts, so their textures need not be resident), every mesh with a fragment
  // on the list (FramePlanOptions::keep_every_mesh), read back at once.
  FrameRecording probe = rec;
  probe.feedback = probe.read_back_list = true;
  probe.wide_first = probe.draw_count;
  TS_TRY(stack_->submit({&probe, Uploads::kAll, false, {}}));
  // The list the frame is drawn with: what the mip ledger's "displayed" looks at (else every mip of a
  // reference run would count as never displayed).
  last_list_ = read_candidates();
  have_list_ = true;
  TS_TRY(load_ground_wanted(index, false));
  if (auto st = load_fully(last_list_, LoadGoal::kWantedLevels); !st) {
    return make_error(st.error().code, "frame " + std::to_string(index) + ": " + st.error().message);
  }
  return ok_status();
}

}  // namespace texstream::render
