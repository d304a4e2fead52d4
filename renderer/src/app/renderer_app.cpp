#include "texstream/render/app/renderer_app.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <optional>
#include <thread>

#include "texstream/common/camera_path.hpp"
#include "texstream/stream/adaptive_controller.hpp"
#include "texstream/render/scene/broad_phase.hpp"
#include "texstream/render/scene/camera.hpp"
#include "texstream/render/frame/frame_capture.hpp"
#include "texstream/render/frame/frame_constants.hpp"
#include "texstream/render/measure/frame_log.hpp"
#include "texstream/render/measure/frame_measurement.hpp"
#include "texstream/render/window/interactive_session.hpp"
#include "texstream/render/scene/gpu_structs.hpp"
#include "texstream/render/scene/scene_data.hpp"
#include "texstream/render/scene/scene_gpu.hpp"
#include "texstream/render/frame/scene_passes.hpp"
#include "texstream/render/vulkan/shader_compiler.hpp"
#include "texstream/stream/stream_client.hpp"
#include "texstream/render/cache/texture_cache.hpp"
#include "texstream/stream/texture_states.hpp"
#include "texstream/render/frame/visibility_list.hpp"
#include "texstream/render/vulkan/vk_check.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

namespace texstream::render {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// A new streaming cycle starts once at most this fraction of the previous cycle's requests is unanswered
// ("mostly answered"), so the server always has work queued but the list stays fresh.
constexpr double kCycleOutstandingFraction = 0.25;
// The wide metadata pass renders at 1/4 of the viewport per axis: it only ranks off-screen meshes.
constexpr uint32_t kWidePassDivisor = 4;

// Seed 000's load time (Table 2: 16 ms) in the two-process design: file reads run in texstream-server, off
// the frame; what a frame still spends on loading is taking completions (check, copy into staging, checksum,
// queue the copy). Once a frame has spent controller.load_time_ms on that, reserve() answers "no room now":
// the client keeps the completion and offers it first next frame. The first mip of a frame always passes.
class LoadTimeSink final : public MipSink {
 public:
  LoadTimeSink(MipSink& inner, Clock::time_point deadline) : inner_(inner), deadline_(deadline) {}
  std::span<std::byte> reserve(TextureId texture, MipLevel mip, uint64_t bytes) override {
    if (taken_ > 0 && Clock::now() >= deadline_) {
      limited_ = true;
      return {};
    }
    auto span = inner_.reserve(texture, mip, bytes);
    if (!span.empty()) ++taken_;
    else no_room_ = true;
    return span;
  }
  void commit(TextureId texture, MipLevel mip, std::span<std::byte> data) override { inner_.commit(texture, mip, data); }
  void reject(TextureId texture, MipLevel mip, std::span<std::byte> reserved) override {
    inner_.reject(texture, mip, reserved);
  }
  void failed(TextureId texture, MipLevel mip, CompletionStatus status) override { inner_.failed(texture, mip, status); }
  bool limited() const { return limited_; }
  bool no_room() const { return no_room_; }  // the staging ring was full: the rest waits for the next frame

 private:
  MipSink& inner_;
  Clock::time_point deadline_;
  uint64_t taken_ = 0;
  bool limited_ = false;
  bool no_room_ = false;
};

// Lock-step: commits (which place textures in cache regions) are applied in (texture, mip) order instead of
// the server's completion order, which its worker threads make nondeterministic; otherwise a texture's region,
// and so the last bit of some filtered texels, would differ between two runs of the same path.
class OrderedCommitSink final : public MipSink {
 public:
  explicit OrderedCommitSink(MipSink& inner) : inner_(inner) {}
  std::span<std::byte> reserve(TextureId texture, MipLevel mip, uint64_t bytes) override {
    return inner_.reserve(texture, mip, bytes);
  }
  void commit(TextureId texture, MipLevel mip, std::span<std::byte> data) override {
    pending_.push_back({texture, mip, data});
  }
  void reject(TextureId texture, MipLevel mip, std::span<std::byte> reserved) override {
    inner_.reject(texture, mip, reserved);
  }
  void failed(TextureId texture, MipLevel mip, CompletionStatus status) override { inner_.failed(texture, mip, status); }
  void flush() {
    std::sort(pending_.begin(), pending_.end(), [](const Pending& a, const Pending& b) {
      return a.texture != b.texture ? a.texture < b.texture : a.mip < b.mip;
    });
    for (const Pending& p : pending_) inner_.commit(p.texture, p.mip, p.data);
    pending_.clear();
  }

 private:
  struct Pending {
    TextureId texture;
    MipLevel mip;
    std::span<std::byte> data;
  };
  MipSink& inner_;
  std::vector<Pending> pending_;
};

// Lock-step (DESIGN "Determinism and measurement"): the longest a frame waits for the server to answer the
// previous cycle before the run is declared stuck. Generous: a cold server on a loaded 2-core machine.
constexpr std::chrono::seconds kLockstepTimeout{60};

// load_fully(): this many rounds in a row that send requests but publish no mip end the load with an error
// instead of spinning (a server that answers everything with retryable failures, a cache that evicts what it
// just loaded). A healthy round publishes at least one mip; 64 rounds is far beyond any retry burst.
constexpr uint32_t kMaxFruitlessLoadRounds = 64;

// render.preload_all ends with an error once this many spawned servers in a row died before attaching to the
// segment: a server that cannot start (a bad option, a missing library, a wrong binary) does not start on the
// next try either, and the restart back-off would otherwise stretch each round to the colormap-only retry
// period (30 s). A streaming run goes on drawing the colormap and keeps retrying, as after any crash; a
// lock-step run ends at the first death (render_frame).
constexpr uint64_t kMaxDeathsBeforeAttach = 3;

bool same_pose(const CameraPose& a, const CameraPose& b) {
  return a.position[0] == b.position[0] && a.position[1] == b.position[1] && a.position[2] == b.position[2] &&
         a.yaw_deg == b.yaw_deg && a.pitch_deg == b.pitch_deg;
}

double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

class Renderer {
 public:
  explicit Renderer(const RenderRun& run) : run_(run), cfg_(run.config) {}
  Result<RunSummary> run();

 private:
  Status set_up();
  Status render_frame(uint64_t index, bool last);
  void start_cycle();
  std::vector<StreamCandidate> read_candidates();
  // Submits cmd_ (recorded) after the cache's sparse binds, waits for it and publishes its uploads.
  Status submit_and_wait();
  // What a submission uploads before its passes: everything committed so far (the texture cache's mips and
  // the meshes made resident), only the mips, only the meshes' geometry, or nothing.
  enum class Uploads { kAll, kMips, kGeometry, kNone };
  // One submission: `uploads`, then `rec`'s passes if given, then the colour capture if `capture`. `first`
  // marks frame 0's stages.
  Status record_and_submit(const FrameRecording* rec, Uploads uploads, bool capture, bool first);
  // A submission that only carries the mips committed so far (no drawing, no geometry).
  Status upload_now();
  // Loads the whole mip chain (down to level 0) of every texture in `wanted`, waiting for the server and
  // uploading as it goes: render.preload_all before frame 0 and render.blocking_loads each frame. With
  // `no_evictions`, an eviction on the way is an error (the preload must fit the cache); otherwise the load
  // stops at the first eviction (a visible set larger than the cache cannot be made fully resident).
  Status load_fully(std::vector<StreamCandidate> wanted, bool no_evictions);
  // An error once kMaxDeathsBeforeAttach servers in a row died before attaching (render.preload_all).
  Status server_can_start() const;
  // An error once `limit` servers in a row refused their configuration (exit status 2) before attaching: a
  // streaming run would otherwise draw the colormap for ever, restarting a server that can never start, and
  // report success. kMaxDeathsBeforeAttach during the run; 1 at its end (a short run ends before a third
  // spawn). Crashes keep the colormap-and-retry rule (docs/faults.md).
  Status server_not_refusing(uint64_t limit) const;
  // server.spawn = false: a standalone server refused the segment (another scene): the run ends, naming it.
  Status standalone_server_not_refusing() const;
  // Frame 0's parts go into the summary after set_up()'s stages (where a start's first frame goes):
  // the time since the previous part, under `name`.
  void first_frame_stage(const char* name);
  // frames.csv: the frame's streaming counters and, with render.reference_dir, its image error.
  Status record_frame(uint64_t index, double time_s, const CameraPose& pose, double latency_ms, double waited_ms);

  const RenderRun& run_;
  const Config& cfg_;
  fs::path output_dir_;
  SceneData scene_;
  std::unique_ptr<CameraPath> path_;
  std::unique_ptr<VulkanContext> ctx_;
  std::unique_ptr<TextureStates> states_;
  std::unique_ptr<TextureCache> cache_;
  std::unique_ptr<SceneGpu> scene_gpu_;
  std::unique_ptr<ShaderCompiler> compiler_;
  std::unique_ptr<ScenePasses> passes_;
  std::unique_ptr<FrameCapture> capture_;
  std::unique_ptr<BroadPhase> broad_phase_;
  std::unique_ptr<StreamClient> client_;
  // After client_: destroyed first, so the in-process server's thread is gone before the segment.
  std::unique_ptr<InProcessServer> in_process_;
  std::unique_ptr<InteractiveSession> interactive_;  // render.window = true only
  UniqueCommandPool pool_;
  VkCommandBuffer cmd_ = VK_NULL_HANDLE;
  UniqueFence fence_;
  std::vector<uint32_t> visible_;
  std::vector<uint32_t> new_textures_;  // textures of the meshes a frame draws for the first time
  Clock::time_point frame0_mark_{};     // first_frame_stage(): end of frame 0's previous part
  std::vector<double> latencies_ms_;
  uint64_t serial_ = 0;
  uint64_t cycles_ = 0;
  uint64_t last_cycle_sent_ = 0;
  uint64_t load_bytes_ = 0;
  // Seed 000 §3.4: s and b for each cycle from the measured frame latencies (docs/controller.md).
  std::unique_ptr<AdaptiveController> controller_;
  double sum_load_mb_ = 0, sum_bias_ = 0, sum_tw_ms_ = 0;  // per-frame sums for the run summary
  uint64_t load_time_limited_frames_ = 0;
  // Per-frame measurements (frame_log.hpp).
  std::vector<FrameRecord> frames_;
  Clock::time_point run_start_{};
  uint64_t deaths_before_frames_ = 0;  // server deaths before frame 0 (render.lockstep allows none after it)
  Clock::duration excluded_{0};  // measurement and PNG time: not part of wall_s
  uint64_t prev_mips_ = 0, prev_bytes_ = 0, prev_hits_ = 0, prev_misses_ = 0;
  std::optional<CameraPose> prev_pose_;
  std::unique_ptr<FrameMeasurement> measure_;  // render.reference_dir set: every frame captured and compared
  std::vector<std::pair<std::string, double>> startup_seconds_;  // set_up()'s stages (RunSummary)
};

Status Renderer::set_up() {
  output_dir_ = cfg_.render.output_dir;
  std::error_code ec;
  fs::create_directories(output_dir_ / "frames", ec);
  if (ec) return make_error(ErrorCode::kIo, "render.output_dir '" + output_dir_.string() + "': " + ec.message());

  // Start-up stages, timed for the summary (texstream-bench cache compares 1 K with 1 M textures).
  auto stage_start = Clock::now();
  auto stage = [&](const char* name) {
    const auto t = Clock::now();
    startup_seconds_.emplace_back(name, std::chrono::duration<double>(t - stage_start).count());
    stage_start = t;
  };
  // Mapped, not read: the start costs the same for any scene size; meshes are checked when first drawn.
  auto scene = SceneData::open(cfg_.scene.dir);
  if (!scene) return scene.error();
  scene_ = std::move(*scene);
  const fs::path path_file = cfg_.render.camera_path.empty() ? scene_.dir / scene_.manifest.camera_path
                                                             : fs::path(cfg_.render.camera_path);
  auto path = CameraPath::load(path_file);
  if (!path) return path.error();
  if (path->keys().empty()) return make_error(ErrorCode::kInvalidArgument, path_file.string() + ": no keyframes");
  path_ = std::make_unique<CameraPath>(std::move(*path));
  stage("scene_load");

  // cache.format = auto takes the scene's texel format; an explicit one must match the scene's textures.
  const TexelFormat format = cache_texel_format(cfg_.cache.format, scene_.manifest.texture_format);
  VulkanContextOptions vo;
  vo.device_substring = cfg_.render.device;
  vo.validation = cfg_.render.validation;
  vo.need_bc1 = format == TexelFormat::kBc1;
  if (cfg_.render.window) {
    // The window first: the Vulkan instance needs its extensions. R records the flight next to the frames.
    auto session = InteractiveSession::open(static_cast<uint32_t>(cfg_.render.width_px),
                                            static_cast<uint32_t>(cfg_.render.height_px), path_->sample(0.0),
                                            output_dir_ / "recorded_camera_path.txt");
    if (!session) return session.error();
    interactive_ = std::move(*session);
    interactive_->configure(vo);
  }
  auto ctx = VulkanContext::create(vo);
  if (!ctx) return ctx.error();
  ctx_ = std::move(*ctx);
  spdlog::info("vulkan device: {}", ctx_->device_name());
  stage("vulkan");

  states_ = std::make_unique<TextureStates>(scene_.shapes());
  TextureCacheOptions co;
  co.format = format;
  co.layer_extent = static_cast<uint32_t>(cfg_.cache.layer_extent_px);
  co.layers = static_cast<uint32_t>(cfg_.cache.layers);
  co.staging_bytes = static_cast<uint64_t>(cfg_.render.staging_bytes);
  co.memory_bytes = static_cast<uint64_t>(cfg_.cache.memory_bytes);
  auto cache = TextureCache::create(*ctx_, co, scene_, *states_);
  if (!cache) return cache.error();
  cache_ = std::move(*cache);
  stage("texture_cache");
  // Load size s and mip bias b: controller.mode adaptive (Eq. 4-7), none (s = s_max, b = 0) or fixed.
  auto controller_params = ControllerParams::from_config(cfg_.controller);
  if (!controller_params) return controller_params.error();
  auto controller = AdaptiveController::create(*controller_params);
  if (!controller) return controller.error();
  controller_ = std::make_unique<AdaptiveController>(std::move(*controller));
  load_bytes_ = controller_->load_bytes();

  auto gpu = SceneGpu::create(*ctx_, scene_);
  if (!gpu) return gpu.error();
  scene_gpu_ = std::make_unique<SceneGpu>(std::move(*gpu));
  stage("scene_gpu_upload");
  compiler_ = std::make_unique<ShaderCompiler>(ShaderCompiler::default_source_dir(), ShaderCompiler::default_cache_dir());
  ScenePassesOptions po;
  po.width = static_cast<uint32_t>(cfg_.render.width_px);
  po.height = static_cast<uint32_t>(cfg_.render.height_px);
  po.wide_width = std::max(16u, po.width / kWidePassDivisor);
  po.wide_height = std::max(16u, po.height / kWidePassDivisor);
  po.debug_view = gpu_debug_view(cfg_.render.debug_view);
  auto passes = ScenePasses::create(*ctx_, *compiler_, po, *scene_gpu_, *cache_);
  if (!passes) return passes.error();
  passes_ = std::move(*passes);
  stage("passes_and_shaders");
  if (interactive_) TS_TRY(interactive_->attach(*ctx_));
  auto capture = FrameCapture::create(*ctx_, po.width, po.height);
  if (!capture) return capture.error();
  capture_ = std::make_unique<FrameCapture>(std::move(*capture));
  broad_phase_ = BroadPhase::for_scene(scene_);  // mesh_index.bin, mapped (built and kept once when missing)
  stage("broad_phase_tree");

  VkDevice device = ctx_->device();
  VkCommandPoolCreateInfo pci{};
  pci.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
  pci.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pci.queueFamilyIndex = ctx_->queue_family();
  VkCommandPool pool = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateCommandPool(device, &pci, nullptr, &pool));
  pool_ = UniqueCommandPool(device, pool);
  VkCommandBufferAllocateInfo ai{};
  ai.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
  ai.commandPool = pool;
  ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  ai.commandBufferCount = 1;
  TS_VK_TRY(vkAllocateCommandBuffers(device, &ai, &cmd_));
  VkFenceCreateInfo fci{};
  fci.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
  VkFence fence = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateFence(device, &fci, nullptr, &fence));
  fence_ = UniqueFence(device, fence);

  if (!cfg_.render.reference_dir.empty()) {
    auto measure = FrameMeasurement::open(cfg_.render.reference_dir, output_dir_, po.width, po.height);
    if (!measure) return measure.error();
    measure_ = std::move(*measure);
  }

  StreamClientOptions so;
  so.spawn_server = !run_.in_process_server && cfg_.server.spawn;
  auto client = StreamClient::start(cfg_, scene_.shapes(), scene_.dir, run_.config_file, run_.overrides, so);
  if (!client) return client.error();
  client_ = std::move(*client);
  stage("stream_client");
  if (run_.in_process_server) {
    in_process_ = run_.in_process_server(cfg_);
    if (!in_process_) return make_error(ErrorCode::kInvalidArgument, "in-process server: the factory made none");
    TS_TRY(in_process_->start(client_->segment().name()));
    spdlog::info("texture server runs in this process (segment '{}')", client_->segment().name());
  }
  if (cfg_.render.preload_all) {
    // Every texture, its whole chain: the reference frames and the all-resident baseline.
    std::vector<StreamCandidate> all;
    std::vector<uint32_t> ids;
    all.reserve(scene_.texture_records().size());
    ids.reserve(scene_.texture_records().size());
    for (uint32_t t = 0; t < scene_.texture_records().size(); ++t) {
      all.push_back({TextureId(t), 0.0f, 1.0f});
      ids.push_back(t);
    }
    TS_TRY(cache_->prepare_textures(ids));  // every entry, and a format check of every texture, up front
    const auto t0 = Clock::now();
    TS_TRY(load_fully(std::move(all), true));
    spdlog::info("render.preload_all: {} mips ({:.1f} MB) of {} textures resident in {:.2f} s",
                 cache_->stats().mips_uploaded, static_cast<double>(cache_->stats().bytes_uploaded) / 1e6,
                 cache_->resident_textures(), ms_between(t0, Clock::now()) / 1e3);
  }
  return ok_status();
}

void Renderer::first_frame_stage(const char* name) {
  const auto t = Clock::now();
  startup_seconds_.emplace_back(name, std::chrono::duration<double>(t - frame0_mark_).count());
  frame0_mark_ = t;
}

Status Renderer::submit_and_wait() {
  VkSubmitInfo si{};
  si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
  si.commandBufferCount = 1;
  si.pCommandBuffers = &cmd_;
  // The copies into the cache need the pages bound just before: a sparse bind is ordered with command
  // buffers only through a semaphore.
  const BindWait bind = cache_->bind_wait();
  const VkPipelineStageFlags bind_stage = VK_PIPELINE_STAGE_ALL_COMMANDS_BIT;
  VkTimelineSemaphoreSubmitInfo bind_ts{};
  bind_ts.sType = VK_STRUCTURE_TYPE_TIMELINE_SEMAPHORE_SUBMIT_INFO;
  bind_ts.waitSemaphoreValueCount = 1;
  bind_ts.pWaitSemaphoreValues = &bind.value;
  if (bind.value != 0) {
    si.pNext = &bind_ts;
    si.waitSemaphoreCount = 1;
    si.pWaitSemaphores = &bind.semaphore;
    si.pWaitDstStageMask = &bind_stage;
  }
  VkDevice device = ctx_->device();
  VkFence fence = fence_.get();
  TS_VK_TRY(vkResetFences(device, 1, &fence));
  TS_VK_TRY(vkQueueSubmit(ctx_->queue(), 1, &si, fence));
  TS_VK_TRY(vkWaitForFences(device, 1, &fence, VK_TRUE, UINT64_MAX));
  cache_->on_submission_complete(serial_);
  return ok_status();
}

Status Renderer::record_and_submit(const FrameRecording* rec, Uploads uploads, bool capture, bool first) {
  ++serial_;
  TS_VK_TRY(vkResetCommandBuffer(cmd_, 0));
  VkCommandBufferBeginInfo bi{};
  bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
  bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  TS_VK_TRY(vkBeginCommandBuffer(cmd_, &bi));
  if (uploads == Uploads::kAll || uploads == Uploads::kMips) {
    TS_TRY(cache_->prepare_uploads(serial_));  // this frame's sparse binds: one vkQueueBindSparse
    cache_->record_uploads(cmd_, serial_);
  }
  if (uploads == Uploads::kAll || uploads == Uploads::kGeometry) TS_TRY(scene_gpu_->record_uploads(scene_, cmd_));
  if (first) first_frame_stage("frame0_record_uploads");
  if (rec) passes_->record(cmd_, *rec);
  if (capture) capture_->record(cmd_, passes_->colour().handle());
  TS_VK_TRY(vkEndCommandBuffer(cmd_));
  TS_TRY(submit_and_wait());
  if (first) first_frame_stage("frame0_gpu");
  return ok_status();
}

Status Renderer::upload_now() { return record_and_submit(nullptr, Uploads::kMips, false, false); }

Status Renderer::server_can_start() const {
  TS_TRY(standalone_server_not_refusing());
  const uint64_t deaths = client_->stats().server_deaths_before_attach;
  if (deaths < kMaxDeathsBeforeAttach) return ok_status();
  return make_error(ErrorCode::kPeerDead,
                    "texstream-server died before attaching to the segment " + std::to_string(deaths) +
                        " times in a row (last: " + client_->last_server_exit() +
                        "); its own messages are above. Check server.executable and the [server] keys");
}

Status Renderer::standalone_server_not_refusing() const {
  if (client_->standalone_refused_by() == 0) return ok_status();
  return make_error(ErrorCode::kPeerDead, client_->last_server_exit() +
                                              ". Start texstream-server with this renderer's scene (--scene, "
                                              "scene.dir), or run this renderer on the server's scene");
}

Status Renderer::server_not_refusing(uint64_t limit) const {
  TS_TRY(standalone_server_not_refusing());
  const uint64_t refusals = client_->server_refusals_before_attach();
  if (refusals < limit) return ok_status();
  return make_error(ErrorCode::kPeerDead,
                    "texstream-server refused to start, " + std::to_string(refusals) +
                        (refusals == 1 ? " time" : " times") + " in a row (last: " +
                        client_->last_server_exit() +
                        ": bad arguments, configuration or scene); its own messages are above. Check the "
                        "[server] and [storage] keys and scene.dir");
}

Status Renderer::load_fully(std::vector<StreamCandidate> wanted, bool no_evictions) {
  // Desired level 0 and no bias: Algorithm 1 then refines each texture one level per round, coarsest first,
  // until its base level is resident (Final). Each round waits for every answer before the next, so the
  // state machine sees the previous level published first.
  for (StreamCandidate& c : wanted) c.desired_mip = 0.0f;
  const uint64_t evictions_before = cache_->stats().evictions;
  uint32_t fruitless = 0;
  auto idle_since = Clock::now();
  for (;;) {
    const uint64_t published_before = cache_->stats().mips_uploaded;
    client_->begin_cycle();
    ++cycles_;
    // A round asks for at most half the staging ring, so all its answers are held and committed at once
    // (in texture order) below: which answers share a poll is timing, and must not decide cache regions.
    const uint64_t round_cap = static_cast<uint64_t>(cfg_.render.staging_bytes) / 2;
    uint64_t round_bytes = 0;
    auto client_send = client_->sender();
    auto send = [&](const MipRequest& r) {
      if (round_bytes > 0 && round_bytes + r.bytes > round_cap) return SendResult::kStop;
      const SendResult sr = client_send(r);
      if (sr == SendResult::kSent) round_bytes += r.bytes;
      return sr;
    };
    const auto result = states_->run_cycle(wanted, std::numeric_limits<uint64_t>::max(), 0.0f, send,
                                           static_cast<size_t>(cfg_.stream.max_mips_per_cycle));
    if (result.sent.empty() && client_->stats().in_flight == 0) {
      // Nothing to send: either every wanted texture is complete (or broken), or the server takes no
      // requests right now (starting, restarting after a crash): then wait for it, within the timeout.
      const auto incomplete = std::count_if(wanted.begin(), wanted.end(), [&](const StreamCandidate& c) {
        const TextureStateView v = states_->view(c.texture);
        return !v.broken && v.resident != 0u;
      });
      if (incomplete == 0) return ok_status();
      if (Clock::now() - idle_since > kLockstepTimeout) {
        const std::string unattached = client_->unattached_reason();
        return make_error(ErrorCode::kTimeout,
                          std::to_string(incomplete) + " textures still incomplete and the server takes no requests (" +
                              to_string(client_->stats().server_state) + ") after " +
                              std::to_string(kLockstepTimeout.count()) + " s" +
                              (unattached.empty() ? "" : ": " + unattached));
      }
      client_->poll(*cache_, 0);  // supervision: reap, restart
      TS_TRY(server_can_start());
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      continue;
    }
    idle_since = Clock::now();
    auto last_progress = Clock::now();
    uint64_t answered = client_->stats().completions_ok;
    OrderedCommitSink ordered(*cache_);  // arrival order must not decide cache regions (reruns identical)
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
                                                   std::to_string(kLockstepTimeout.count()) + " s while loading "
                                                   "whole mip chains");
      } else if (client_->stats().in_flight > 0) {
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      }
    }
    ordered.flush();
    TS_TRY(upload_now());
    if (cache_->stats().evictions != evictions_before) {
      if (no_evictions) {
        return make_error(ErrorCode::kResourceExhausted,
                          "render.preload_all: the cache evicted textures while loading the whole scene; raise "
                          "cache.memory_bytes (now " + std::to_string(cfg_.cache.memory_bytes) +
                              ") and cache.layers (now " + std::to_string(cfg_.cache.layers) + ")");
      }
      return ok_status();  // the visible set does not fit: draw with what is resident
    }
    fruitless = cache_->stats().mips_uploaded == published_before ? fruitless + 1 : 0;
    if (fruitless >= kMaxFruitlessLoadRounds) {
      return make_error(ErrorCode::kTimeout, std::to_string(kMaxFruitlessLoadRounds) +
                                                 " load rounds in a row published no mip (" +
                                                 std::to_string(result.sent.size()) + " requests in the last)");
    }
  }
}

Status Renderer::render_frame(uint64_t index, bool last) {
  const auto t0 = Clock::now();
  frame0_mark_ = t0;
  const double time_s = static_cast<double>(index) * cfg_.render.frame_time_ms / 1000.0;
  CameraLens lens{cfg_.render.fov_y_deg, cfg_.render.offscreen_fov_y_deg,
                  static_cast<double>(cfg_.render.width_px) / static_cast<double>(cfg_.render.height_px),
                  cfg_.render.near_m, cfg_.render.far_m};
  const CameraPose pose = interactive_ ? interactive_->next_pose() : path_->sample(time_s);
  const Camera cam = make_camera(pose, lens);

  // Broad phase over the wide frustum: the wide pass needs those meshes too.
  broad_phase_->query(Frustum::from_matrix(cam.wide_proj * cam.view), cam.position, visible_);
  FrameRecording rec;
  // Touching / outside the viewport's frustum: the main pass draws the first run, the wide pass the second
  // (W = 1 for meshes outside the viewport, seed 000 §3.2).
  ViewportSplit split =
      broad_phase_->split_by_viewport(Frustum::from_matrix(cam.proj * cam.view), cam.position, visible_);
  rec.main = main_pass_constants(cam);
  const auto& po = passes_->options();
  rec.wide = wide_pass_constants(cam, cfg_.render.fov_y_deg, cfg_.render.offscreen_fov_y_deg, po.height,
                                 po.wide_height);
  // Meshes that cover no pixel centre of the passes drawing them have no fragment: neither uploaded nor drawn.
  const uint32_t bits = ctx_->properties().limits.subPixelPrecisionBits;
  split = broad_phase_->drop_unsampled(
      SampleGrid::from_columns(rec.main.view_proj.m, po.width, po.height, bits),
      SampleGrid::from_columns(rec.wide.view_proj.m, po.wide_width, po.wide_height, bits), cam.position, visible_,
      split);
  if (index == 0) first_frame_stage("frame0_broad_phase");
  // Meshes drawn for the first time: checked, their geometry queued for this frame's command buffer and their
  // textures' table entries written, so the frame draws every one of them.
  new_textures_.clear();
  TS_TRY(scene_gpu_->make_resident(scene_, visible_, &new_textures_));
  if (index == 0) first_frame_stage("frame0_make_resident");
  TS_TRY(cache_->prepare_textures(new_textures_));
  if (index == 0) first_frame_stage("frame0_texture_entries");
  scene_gpu_->write_draws(scene_, visible_, cam.position, split, rec);
  if (index == 0) first_frame_stage("frame0_draw_list");
  // The same constants the offline ViewRenderer uses (frame_constants.hpp); ScenePasses::record adds the
  // view mode and the feedback bit.
  *scene_gpu_->frame_uniforms.as<gpu::FrameUniforms>() =
      frame_uniforms(cam, cfg_, scene_gpu_->mesh_count, scene_gpu_->compact_capacity, cache_->layer_extent(),
                     cache_->mip_levels());

  // Completions that arrived since the last frame: validated by the client, copied into the staging ring.
  // Real time: at most controller.load_time_ms of this frame goes to it (LoadTimeSink), and whatever has not
  // arrived waits for a later frame. Lock-step: the frame first takes every answer to the previous cycle (or
  // as many as the staging ring holds), so what it shows depends on the frame index only, not on timing.
  Clock::duration waited{0};
  if (cfg_.render.lockstep) {
    const auto wait_start = Clock::now();
    OrderedCommitSink ordered(*cache_);
    LoadTimeSink all(ordered, Clock::time_point::max());
    while (client_->stats().in_flight > 0) {
      client_->poll(all, std::numeric_limits<size_t>::max());
      if (all.no_room() || client_->stats().in_flight == 0) break;
      if (Clock::now() - wait_start > kLockstepTimeout) {
        return make_error(ErrorCode::kTimeout, "render.lockstep: " + std::to_string(client_->stats().in_flight) +
                                                   " requests still unanswered after " +
                                                   std::to_string(kLockstepTimeout.count()) + " s");
      }
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
    ordered.flush();  // the whole frame's arrivals, in (texture, mip) order
    waited = Clock::now() - wait_start;
    // A server that died took its requests along: what the next frames show would depend on when it came
    // back, which is what lock-step promises to rule out (and a server that cannot start would leave a run of
    // colormap frames that reports success).
    if (client_->stats().server_deaths != deaths_before_frames_) {
      return make_error(ErrorCode::kPeerDead, "render.lockstep: texstream-server died during the run (" +
                                                  client_->last_server_exit() +
                                                  "); its frames would depend on when it came back");
    }
  } else {
    LoadTimeSink timed(*cache_, Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                                   std::chrono::duration<double, std::milli>(cfg_.controller.load_time_ms)));
    client_->poll(timed, static_cast<size_t>(cfg_.stream.max_mips_per_cycle));
    if (timed.limited()) ++load_time_limited_frames_;
    TS_TRY(server_not_refusing(kMaxDeathsBeforeAttach));
  }
  const uint64_t in_flight = client_->stats().in_flight;
  // Only a frame that starts a streaming cycle has its compacted list read; any other frame's list would be
  // reset unseen by the next frame's compaction. So the metadata writes, the wide pass and the compaction run
  // on exactly those frames, and the frames in between draw only the picture (render.feedback = false: never,
  // so no streaming cycle either).
  rec.read_back_list = cfg_.render.feedback && static_cast<double>(in_flight) <=
                                                   kCycleOutstandingFraction * static_cast<double>(last_cycle_sent_);
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
  Clock::duration not_frame_time = waited;  // in neither latency
  Clock::duration twin_time{0};
  auto draw_twin = [&]() -> Status {
    FrameRecording off = rec;
    off.feedback = off.read_back_list = false;
    const auto d0 = Clock::now();
    TS_TRY(record_and_submit(&off, Uploads::kNone, false, false));
    twin_time = Clock::now() - d0;
    return ok_status();
  };
  if (pairs) {
    const auto u0 = Clock::now();
    TS_TRY(record_and_submit(nullptr, Uploads::kGeometry, false, false));
    not_frame_time += Clock::now() - u0;
  }
  const bool twin_first = pairs && index % 2 == 0;
  if (twin_first) TS_TRY(draw_twin());
  const auto own_start = Clock::now();
  // Every frame is captured when it is measured against a reference (the copy is part of every measured
  // configuration alike, so ratios between them are unaffected).
  TS_TRY(record_and_submit(&rec, Uploads::kAll, write || measure_, index == 0));
  if (index == 0) {
    spdlog::info("first frame: {} meshes in the wide frustum ({} in the viewport's), {} meshes of {} uploaded ({:.1f} MB)",
                 visible_.size(), split.main_end, scene_gpu_->stats().meshes_resident, scene_gpu_->mesh_count,
                 static_cast<double>(scene_gpu_->stats().bytes_uploaded) / 1e6);
  }
  if (interactive_) {
    InteractiveReadout r;
    r.frame_latency_ms = latencies_ms_.empty() ? 0.0 : latencies_ms_.back();
    r.bytes_uploaded_total = cache_->stats().bytes_uploaded;
    r.textures_resident = cache_->resident_textures();
    r.texture_count = scene_.texture_records().size();
    r.load_size_mb = static_cast<double>(load_bytes_) / 1e6;
    TS_TRY(interactive_->present(passes_->colour().handle(), passes_->options().width, passes_->options().height, r));
  }
  if (rec.read_back_list) {
    if (cfg_.render.blocking_loads) {
      TS_TRY(load_fully(read_candidates(), false));  // the next frame draws every named texture complete
    } else {
      start_cycle();
    }
  }
  if (index == 0) first_frame_stage("frame0_cycle");
  const auto own_end = Clock::now();
  if (pairs && !twin_first) TS_TRY(draw_twin());
  // Lock-step waits for the server are not frame latency: they would not exist in real time.
  const Clock::duration shared = own_start - t0 - not_frame_time - (twin_first ? twin_time : Clock::duration{0});
  latencies_ms_.push_back(std::chrono::duration<double, std::milli>(shared + (own_end - own_start)).count());
  // Δt of Eq. 4-7 is in seconds; the next cycle uses the s and b this frame leads to.
  controller_->on_frame(latencies_ms_.back() / 1e3);
  sum_load_mb_ += controller_->load_size_bytes() / 1e6;
  sum_bias_ += controller_->mip_bias();
  sum_tw_ms_ += controller_->weighted_latency_s() * 1e3;

  const auto measure_start = Clock::now();
  TS_TRY(record_frame(index, time_s, pose, latencies_ms_.back(), std::chrono::duration<double, std::milli>(waited).count()));
  if (pairs) frames_.back().latency_off_ms = std::chrono::duration<double, std::milli>(shared + twin_time).count();
  if (write) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05llu.png", static_cast<unsigned long long>(index));
    TS_TRY(capture_->write_png(output_dir_ / "frames" / name));
  }
  excluded_ += Clock::now() - measure_start;
  return ok_status();
}

Status Renderer::record_frame(uint64_t index, double time_s, const CameraPose& pose, double latency_ms,
                              double waited_ms) {
  const auto now = Clock::now();
  const TextureCacheStats& cs = cache_->stats();
  const StreamStats ss = client_->stats();
  FrameRecord f;
  f.index = index;
  f.time_s = time_s;
  f.wall_s = std::chrono::duration<double>(now - run_start_ - excluded_).count();
  f.latency_ms = latency_ms;
  f.waited_ms = waited_ms;
  f.tw_ms = controller_->weighted_latency_s() * 1e3;
  f.load_size_mb = controller_->load_size_bytes() / 1e6;
  f.mip_bias = controller_->mip_bias();
  f.mips = cs.mips_uploaded - prev_mips_;
  f.bytes = cs.bytes_uploaded - prev_bytes_;
  prev_mips_ = cs.mips_uploaded;
  prev_bytes_ = cs.bytes_uploaded;
  f.bound_pages = cache_->page_bytes() ? cache_->bound_bytes() / cache_->page_bytes() : 0;
  const uint64_t hits = ss.server_ram_cache_hits - std::min(prev_hits_, ss.server_ram_cache_hits);
  const uint64_t misses = ss.server_ram_cache_misses - std::min(prev_misses_, ss.server_ram_cache_misses);
  prev_hits_ = ss.server_ram_cache_hits;
  prev_misses_ = ss.server_ram_cache_misses;
  f.server_hit_rate = hits + misses ? static_cast<double>(hits) / static_cast<double>(hits + misses)
                                    : std::numeric_limits<double>::quiet_NaN();
  f.in_flight = ss.in_flight;
  f.camera_still = prev_pose_ && same_pose(*prev_pose_, pose);
  prev_pose_ = pose;
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  f.mse = f.psnr_db = f.ssim = f.popin_mse = f.latency_off_ms = kNaN;
  if (measure_) TS_TRY(measure_->add(capture_->pixels().first(size_t{capture_->width()} * capture_->height() * 4)));
  frames_.push_back(f);
  return ok_status();
}


std::vector<StreamCandidate> Renderer::read_candidates() {
  const auto* header = scene_gpu_->readback.as<gpu::CompactListHeader>();
  const uint32_t count = std::min(header->count, scene_gpu_->compact_capacity);
  const auto* entries = reinterpret_cast<const gpu::CompactEntry*>(scene_gpu_->readback.bytes().data() +
                                                                   sizeof(gpu::CompactListHeader));
  uint64_t skipped = 0;
  const auto candidates =
      build_candidates({entries, count}, scene_.mesh_records().size(), scene_.texture_records().size(), &skipped);
  if (skipped) spdlog::warn("visibility list: {} entries with a bad mesh id skipped", skipped);
  return candidates;
}

void Renderer::start_cycle() {
  const auto candidates = read_candidates();
  client_->begin_cycle();
  ++cycles_;
  // stream.max_mips_per_cycle caps the requests of one cycle on top of the load size s.
  uint64_t sent = 0;
  const auto max_mips = static_cast<uint64_t>(cfg_.stream.max_mips_per_cycle);
  auto send = client_->sender();
  // Algorithm 1: the cycle stops at load size s and refines a texture only while desired + b < resident.
  load_bytes_ = controller_->load_bytes();
  const auto bias = static_cast<float>(controller_->mip_bias());
  const auto result = states_->run_cycle(candidates, load_bytes_, bias, [&](const MipRequest& r) {
    if (sent >= max_mips) return SendResult::kStop;
    const SendResult s = send(r);
    if (s == SendResult::kSent) ++sent;
    return s;
  });
  last_cycle_sent_ = result.sent.size();
  spdlog::debug("cycle {}: {} candidates, {} requests, {} bytes", cycles_, candidates.size(), result.sent.size(),
                result.bytes);
}

Result<RunSummary> Renderer::run() {
  TS_TRY(set_up());
  uint64_t frames = static_cast<uint64_t>(cfg_.render.frames);
  if (frames == 0) frames = static_cast<uint64_t>(std::floor(path_->duration_s() * 1000.0 / cfg_.render.frame_time_ms)) + 1;
  // Window mode with render.frames = 0 runs until the window is closed.
  if (interactive_ && cfg_.render.frames == 0) frames = UINT64_MAX;
  uint64_t rendered = 0;
  run_start_ = Clock::now();
  // Per-frame deltas start here: the preload (render.preload_all) is not frame 0's streaming.
  prev_mips_ = cache_->stats().mips_uploaded;
  prev_bytes_ = cache_->stats().bytes_uploaded;
  prev_hits_ = client_->stats().server_ram_cache_hits;
  prev_misses_ = client_->stats().server_ram_cache_misses;
  deaths_before_frames_ = client_->stats().server_deaths;
  // render.pace_frames: the camera path advances frame_time_ms per frame, so without pacing a device that
  // draws a frame in 0.5 ms flies the path 60x faster than real time and the streaming never keeps up. The
  // wait is not part of the frame's latency (render_frame measures from its own start).
  const bool pace = cfg_.render.pace_frames && !cfg_.render.lockstep && !interactive_;
  const auto frame_period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double, std::milli>(cfg_.render.frame_time_ms));
  for (uint64_t i = 0; i < frames && !(interactive_ && interactive_->closed()); ++i, ++rendered) {
    if (pace) std::this_thread::sleep_until(run_start_ + frame_period * static_cast<int64_t>(i));
    TS_TRY(render_frame(i, i + 1 == frames));
  }
  frames = rendered;
  if (interactive_) TS_TRY(interactive_->finish());
  TS_VK_TRY(vkDeviceWaitIdle(ctx_->device()));
  TS_TRY(server_not_refusing(1));  // the run ended with no server since the last refusal

  const StreamStats ss = client_->stats();
  RunSummary s;
  s.device = ctx_->device_name();
  s.output_dir = fs::absolute(output_dir_);
  s.frames = frames;
  s.frame_latency = LatencyStats::from(latencies_ms_);
  s.mips_streamed = cache_->stats().mips_uploaded;
  s.mb_streamed = static_cast<double>(cache_->stats().bytes_uploaded) / 1e6;
  const uint64_t lookups = ss.server_ram_cache_hits + ss.server_ram_cache_misses;
  s.server_ram_hit_rate = lookups ? static_cast<double>(ss.server_ram_cache_hits) / static_cast<double>(lookups) : 0.0;
  s.protocol_errors = ss.protocol_errors;
  s.server_restarts = ss.server_restarts;
  s.textures_resident = cache_->resident_textures();
  s.texture_count = scene_.texture_records().size();
  s.streaming_cycles = cycles_;
  s.evictions = cache_->stats().evictions;
  s.controller_mode = to_string(controller_->params().mode);
  const double n = frames ? static_cast<double>(frames) : 1.0;
  s.avg_load_size_mb = sum_load_mb_ / n;
  s.avg_mip_bias = sum_bias_ / n;
  s.avg_weighted_latency_ms = sum_tw_ms_ / n;
  s.load_time_limited_frames = load_time_limited_frames_;
  s.controller_rejected_frames = controller_->frames_rejected();
  s.startup_seconds = startup_seconds_;
  TS_TRY(cache_->write_stats_json(output_dir_ / "cache.json"));  // budget checks, binds, thrash rate
  if (measure_) {
    TS_TRY(measure_->measure(frames_));
    measure_.reset();  // removes the spill file
  }
  TS_TRY(write_frame_log(output_dir_ / "frames.csv", frames_));
  // Shut the server down and release the device before the validation counts are read: teardown is validated too.
  if (in_process_) in_process_->stop();  // before the client unmaps the segment it serves
  in_process_.reset();
  client_.reset();
  passes_.reset();
  capture_.reset();
  scene_gpu_.reset();
  cache_.reset();
  fence_.reset();
  pool_.reset();
  s.validation_errors = ctx_->validation_errors();
  s.validation_warnings = ctx_->validation_warnings();
  TS_TRY(s.write_json(output_dir_ / "summary.json"));
  return s;
}

}  // namespace

Result<RunSummary> run_renderer(const RenderRun& run) {
  Renderer r(run);
  return r.run();
}

}  // namespace texstream::render
