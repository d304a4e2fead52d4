// The frame loop of texstream-render, top-down (renderer.hpp says where the rest of the class lives). Per
// frame, as seed 000's Algorithm 1 around the rooms: plan the frame (broad phase, draw lists), take the
// completions that arrived, draw it with the metadata pass and compaction, and when the previous cycle is
// mostly answered read the compacted list back and start the next streaming cycle; then the controller
// turns the frame's latency into the next cycle's load size s and mip bias b.
#include "texstream/render/app/renderer_app.hpp"

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <thread>

#include "renderer.hpp"
#include "texstream/render/frame/frame_capture.hpp"
#include "texstream/render/frame/frame_plan.hpp"
#include "texstream/render/vulkan/vk_check.hpp"
#include "texstream/render/window/interactive_session.hpp"

namespace texstream::render {

namespace {

namespace fs = std::filesystem;

// A new streaming cycle starts once at most this fraction of the previous cycle's requests is unanswered
// ("mostly answered"), so the server always has work queued but the list stays fresh.
constexpr double kCycleOutstandingFraction = 0.25;

double ms(std::chrono::steady_clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

}  // namespace

Renderer::Renderer(const RenderRun& run) : run_(run), cfg_(run.config) {}
Renderer::~Renderer() = default;

Result<RunSummary> Renderer::run() {
  TS_TRY(set_up());
  uint64_t frames = static_cast<uint64_t>(cfg_.render.frames);
  if (frames == 0)
    frames = static_cast<uint64_t>(std::floor(path_->duration_s() * 1000.0 / cfg_.render.frame_time_ms)) + 1;
  // Window mode with render.frames = 0 runs until the window is closed.
  if (interactive_ && cfg_.render.frames == 0) frames = UINT64_MAX;
  run_start_ = Clock::now();
  // Per-frame shares start here: the preload (render.preload_all) is not frame 0's streaming.
  record_.start(counters(), run_start_);
  deaths_before_frames_ = client_->stats().server_deaths;
  // render.pace_frames: the camera path advances frame_time_ms per frame, so without pacing a device that
  // draws a frame in 0.5 ms flies the path 60x faster than real time and the streaming never keeps up. The
  // wait is not part of the frame's latency (render_frame measures from its own start).
  const bool pace =
      cfg_.render.pace_frames && !cfg_.render.lockstep && !cfg_.render.load_wanted_before_drawing && !interactive_;
  const auto frame_period =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double, std::milli>(cfg_.render.frame_time_ms));
  for (uint64_t i = 0; i < frames && !(interactive_ && interactive_->closed()); ++i) {
    if (pace) std::this_thread::sleep_until(run_start_ + frame_period * static_cast<int64_t>(i));
    TS_TRY(render_frame(i, i + 1 == frames));
  }
  return finish();
}

Status Renderer::render_frame(uint64_t index, bool last) {
  const auto t0 = Clock::now();
  stage_mark_ = t0;
  const uint64_t uploaded_before = stack_->cache().stats().bytes_uploaded;
  const uint64_t mips_before = stack_->cache().stats().mips_uploaded;
  const bool first = index == 0;
  const auto frame0_step = [this](const char* name) { first_frame_stage(name); };
  const double time_s = static_cast<double>(index) * cfg_.render.frame_time_ms / 1000.0;
  const CameraPose pose = interactive_ ? interactive_->next_pose() : path_->sample(time_s);
  const Camera cam = make_camera(pose, lens_);

  // 1. What the frame draws: broad phase, viewport split, unsampled meshes dropped, new meshes made
  //    resident, draw lists and frame constants (frame_plan.hpp).
  const bool load_wanted_first = cfg_.render.load_wanted_before_drawing;
  FramePlanOptions plan_options;
  if (first) plan_options.step = frame0_step;
  plan_options.keep_every_mesh = load_wanted_first;
  auto plan = plan_frame(*stack_, cam, cfg_, plan_options);
  if (!plan) return plan.error();
  FrameRecording& rec = plan->rec;
  const auto intake_start = Clock::now();
  const double plan_ms = ms(intake_start - t0);

  // 2. The completions that arrived since the last frame, into the staging ring.
  auto waited = take_completions();
  if (!waited) return waited.error();
  const double intake_ms = ms(Clock::now() - intake_start - *waited);
  // 2b. render.load_wanted_before_drawing (reference frames): the frame is drawn once with feedback, every mip
  //     it samples is loaded, and only then drawn below, without feedback. Like the lock-step wait, not frame
  //     latency: a real-time run has no such pass (docs/design/reference_frames.md).
  if (load_wanted_first) {
    const auto l0 = Clock::now();
    TS_TRY(load_wanted(rec, index));
    *waited += Clock::now() - l0;
  }

  // 3. Only a frame that starts a streaming cycle has its compacted list read; any other frame's list would
  //    be reset unseen by the next frame's compaction. So the metadata writes, the wide pass and the
  //    compaction run on exactly those frames, and the frames in between draw only the picture
  //    (render.feedback = false: never, so no streaming cycle either).
  const uint64_t in_flight = client_->stats().in_flight;
  rec.read_back_list =
      cfg_.render.feedback && !load_wanted_first &&
      static_cast<double>(in_flight) <= kCycleOutstandingFraction * static_cast<double>(last_cycle_sent_);
  rec.feedback = rec.read_back_list;
  const bool write = last || (cfg_.render.write_every_frames > 0 &&
                              index % static_cast<uint64_t>(cfg_.render.write_every_frames) == 0);

  // render.feedback_pairs: the frame is drawn a second time without feedback, from the same pose and draw
  // lists, before or after the real one (alternating, so neither always runs on warmer caches). Its latency is
  // the frame's CPU part up to here plus its own submission. The geometry of meshes drawn for the first time
  // goes first, in a submission of its own that neither latency counts (the first drawing would otherwise pay
  // it alone); the texture cache's uploads stay in the real frame, which is then exactly the frame a run
  // without pairs draws (its new mips show from the next frame on; the twin uploads nothing).
  const bool pairs = cfg_.render.feedback_pairs;
  Clock::duration not_frame_time = *waited;  // in neither latency
  Clock::duration twin_time{0};
  auto draw_twin = [&]() -> Status {
    FrameRecording off = rec;
    off.feedback = off.read_back_list = false;
    const auto d0 = Clock::now();
    TS_TRY(stack_->submit({&off, Uploads::kNone, false, {}}));
    twin_time = Clock::now() - d0;
    return ok_status();
  };
  if (pairs) {
    const auto u0 = Clock::now();
    TS_TRY(stack_->submit({nullptr, Uploads::kGeometry, false, {}}));
    not_frame_time += Clock::now() - u0;
  }
  const bool twin_first = pairs && index % 2 == 0;
  if (twin_first) TS_TRY(draw_twin());

  // 4. Draw: the uploads, the passes and, for a written or measured frame, the colour capture (the copy is
  //    part of every measured configuration alike, so ratios between them are unaffected). Fades (stream.fade_ms)
  //    advance by the path's time per frame, so lock-step runs fade alike; with stream.fade_when = still a
  //    frame whose camera moved ends them all (in motion a pop hides among the frame's changes; blend.md).
  const bool still = last_pose_ && same_pose(*last_pose_, pose);
  const bool end_fades = !still && cfg_.stream.fade_when == FadeWhen::kStill;
  stack_->cache().advance_fades(first       ? 0.0
                                : end_fades ? std::numeric_limits<double>::infinity()
                                            : cfg_.render.frame_time_ms / 1e3);
  const auto own_start = Clock::now();
  TS_TRY(stack_->submit({&rec, Uploads::kAll, write || record_.compares(), first ? frame0_step : StepHook{}}));
  const RenderStack::SubmitTimes submit_times = stack_->last_times();
  if (first) {
    spdlog::info(
        "first frame: {} meshes in the wide frustum ({} in the viewport's), {} meshes of {} uploaded ({:.1f} MB)",
        stack_->visible().size(), plan->split.main_end, stack_->scene_gpu().stats().meshes_resident,
        stack_->scene_gpu().mesh_count(), static_cast<double>(stack_->scene_gpu().stats().bytes_uploaded) / 1e6);
  }
  if (interactive_) {
    InteractiveReadout r;
    r.frame_latency_ms = record_.last_latency_ms();
    r.bytes_uploaded_total = stack_->cache().stats().bytes_uploaded;
    r.textures_resident = stack_->cache().resident_textures();
    r.texture_count = scene_.texture_records().size();
    r.load_size_mb = static_cast<double>(load_bytes_) / 1e6;
    const ScenePasses& passes = stack_->passes();
    TS_TRY(interactive_->present(passes.colour().handle(), passes.options().width, passes.options().height, r));
  }

  // 5. The streaming cycle (Algorithm 1) on the list this frame read back, and the ground's pages this frame's
  //    needbuffer asks for (pages.per_frame): in the cycle's generation (an older one would be superseded by it
  //    at once) and ahead of its mips, so that they cannot take every place in flight.
  const auto pages = [&] { request_ground_pages(index, pose); };
  const auto cycle_start = Clock::now();
  if (rec.read_back_list) {
    last_list_ = read_candidates();
    have_list_ = true;
    if (cfg_.render.blocking_loads) {
      // The next frame draws every named texture complete.
      TS_TRY(load_fully(last_list_, LoadGoal::kWholeChains));
      pages();
    } else {
      start_cycle(last_list_, pages);
    }
  } else {
    pages();
  }
  if (first) first_frame_stage("cycle");
  last_pose_ = pose;
  const auto own_end = Clock::now();
  const double cycle_ms = ms(own_end - cycle_start);
  if (pairs && !twin_first) TS_TRY(draw_twin());

  // 6. The frame's latency (lock-step waits for the server are not frame latency: they would not exist in
  //    real time); Δt is in seconds, and the next cycle uses the s and b this frame leads to.
  const Clock::duration shared = own_start - t0 - not_frame_time - (twin_first ? twin_time : Clock::duration{0});
  const double latency_ms = ms(shared + (own_end - own_start));
  // The frame's uploads let mode auto tell its streaming work from its rendering (headroom_controller.hpp).
  controller_->on_frame(latency_ms / 1e3, static_cast<double>(stack_->cache().stats().bytes_uploaded - uploaded_before),
                        static_cast<double>(stack_->cache().stats().mips_uploaded - mips_before));
  tell_states();

  // 7. The frame's record (frames.csv) and, with render.write_every_frames, its PNG: not the run's time. The
  //    mip deficit is the latest list's against what is resident now, after the events of step 6: the
  //    residency the next frame draws with.
  const auto measure_start = Clock::now();
  StreamQuality quality;
  quality.list_fresh = rec.read_back_list;
  quality.mip_deficit = have_list_ ? mip_use_->observe(last_list_) : std::numeric_limits<double>::quiet_NaN();
  FrameCapture& capture = stack_->capture();
  const auto pixels = record_.compares() ? capture.pixels().first(size_t{capture.width()} * capture.height() * 4)
                                         : std::span<const std::byte>{};
  auto frame =
      record_.add(index, time_s, pose, latency_ms, ms(*waited), counters(), controller_readout(), quality, pixels);
  if (!frame) return frame.error();
  if (pairs) (*frame)->latency_off_ms = ms(shared + twin_time);
  FrameRecord& parts = **frame;
  parts.plan_ms = plan_ms;
  parts.intake_ms = intake_ms;
  parts.bind_ms = submit_times.bind_ms;
  parts.record_ms = submit_times.record_ms;
  parts.gpu_ms = submit_times.gpu_ms;
  parts.cycle_ms = cycle_ms;
  if (write) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05llu.png", static_cast<unsigned long long>(index));
    TS_TRY(capture.write_png(output_dir_ / "frames" / name));
  }
  record_.exclude(Clock::now() - measure_start);
  return ok_status();
}

void Renderer::first_frame_stage(const char* name) {
  const auto t = Clock::now();
  startup_seconds_.emplace_back(std::string("frame0_") + name, std::chrono::duration<double>(t - stage_mark_).count());
  stage_mark_ = t;
}

FrameCounters Renderer::counters() const {
  const TextureCache& cache = stack_->cache();
  const stream::StreamStats ss = client_->stats();
  FrameCounters c;
  c.mips_uploaded = cache.stats().mips_uploaded;
  c.bytes_uploaded = cache.stats().bytes_uploaded;
  c.bound_pages = cache.page_bytes() ? cache.bound_bytes() / cache.page_bytes() : 0;
  c.server_hits = ss.server_ram_cache_hits;
  c.server_misses = ss.server_ram_cache_misses;
  c.in_flight = ss.in_flight;
  c.wasted_bytes = mip_use_->bytes_wasted();
  return c;
}

ControllerReadout Renderer::controller_readout() const {
  const double pace = controller_->pace_mips();
  return {controller_->weighted_latency_s() * 1e3, controller_->load_size_bytes() / 1e6, controller_->mip_bias(),
          pace < stream::HeadroomController::kNoPace ? pace : std::numeric_limits<double>::quiet_NaN()};
}

Result<RunSummary> Renderer::finish() {
  if (interactive_) TS_TRY(interactive_->finish());
  TS_VK_TRY(vkDeviceWaitIdle(stack_->context().device()));
  TS_TRY(server_not_refusing(1));  // the run ended with no server since the last refusal

  const TextureCache& cache = stack_->cache();
  const stream::StreamStats ss = client_->stats();
  RunSummary s;
  s.device = stack_->context().device_name();
  s.output_dir = fs::absolute(output_dir_);
  record_.summarise(s);
  s.mips_streamed = cache.stats().mips_uploaded;
  s.mb_streamed = static_cast<double>(cache.stats().bytes_uploaded) / 1e6;
  const uint64_t lookups = ss.server_ram_cache_hits + ss.server_ram_cache_misses;
  s.server_ram_hit_rate = lookups ? static_cast<double>(ss.server_ram_cache_hits) / static_cast<double>(lookups) : 0.0;
  s.protocol_errors = ss.protocol_errors;
  s.server_restarts = ss.server_restarts;
  s.stream_json = stream::stream_stats_json(ss, client_->ipc_time()).dump();
  s.textures_resident = cache.resident_textures();
  s.texture_count = scene_.texture_records().size();
  s.streaming_cycles = cycles_;
  s.evictions = cache.stats().evictions;
  s.textures_refused = TextureTally::of(cache.refused_textures());
  s.textures_charged = TextureTally::of(client_->quarantine().charged_ids());
  s.textures_quarantined = TextureTally::of(client_->quarantine().quarantined_ids());
  s.controller_mode = std::string(choice_name(controller_->params().mode));
  s.controller_rejected_frames = controller_->frames_rejected();
  s.startup_seconds = startup_seconds_;
  if (const GroundPages* g = stack_->ground()) {
    s.ground.has_ground = true;
    s.ground.pages_requested = g->stats().pages_requested;
    s.ground.pages_uploaded = g->stats().pages_uploaded;
    s.ground.pages_failed = g->stats().pages_failed;
    s.ground.pages_cancelled = g->stats().pages_cancelled;
    s.ground.pages_refused = g->stats().pages_refused;
    s.ground.evictions = g->stats().evictions;
    s.ground.frames = g->frames().frames();
    s.ground.frames_used = g->frames().used_frames();
    s.ground.needs_last_frame = g->stats().needs_last_frame;
  }
  mip_use_->finish();  // mips still resident leave: those never displayed are wasted too
  s.wasted_bytes = mip_use_->bytes_wasted();
  s.wasted_bytes_frac = mip_use_->wasted_fraction();
  TS_TRY(cache.write_stats_json(output_dir_ / "cache.json"));  // budget checks, binds, thrash rate
  TS_TRY(record_.finish(output_dir_));
  // Shut the server down and release the device before the validation counts are read: teardown is validated too.
  if (in_process_) in_process_->stop();  // before the client unmaps the segment it serves
  in_process_.reset();
  client_.reset();
  TS_TRY(stack_->tear_down());
  s.validation_errors = stack_->context().validation_errors();
  s.validation_warnings = stack_->context().validation_warnings();
  TS_TRY(s.write_json(output_dir_ / "summary.json"));
  return s;
}

Result<RunSummary> run_renderer(const RenderRun& run) {
  Renderer r(run);
  return r.run();
}

}  // namespace texstream::render
