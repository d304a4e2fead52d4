#include "texstream/render/renderer_app.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <thread>

#include "texstream/common/camera_path.hpp"
#include "texstream/render/adaptive_controller.hpp"
#include "texstream/render/broad_phase.hpp"
#include "texstream/render/camera.hpp"
#include "texstream/render/frame_capture.hpp"
#include "texstream/render/frame_constants.hpp"
#include "texstream/render/interactive_session.hpp"
#include "texstream/render/gpu_structs.hpp"
#include "texstream/render/scene_data.hpp"
#include "texstream/render/scene_gpu.hpp"
#include "texstream/render/scene_passes.hpp"
#include "texstream/render/shader_compiler.hpp"
#include "texstream/render/stream_client.hpp"
#include "texstream/render/texture_cache.hpp"
#include "texstream/render/texture_states.hpp"
#include "texstream/render/visibility_list.hpp"
#include "texstream/render/vk_check.hpp"
#include "texstream/render/vulkan_context.hpp"

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

class Renderer {
 public:
  explicit Renderer(const RenderRun& run) : run_(run), cfg_(run.config) {}
  Result<RunSummary> run();

 private:
  Status set_up();
  Status render_frame(uint64_t index, bool last);
  void start_cycle();

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
  std::unique_ptr<InteractiveSession> interactive_;  // render.window = true only
  UniqueCommandPool pool_;
  VkCommandBuffer cmd_ = VK_NULL_HANDLE;
  UniqueFence fence_;
  std::vector<uint32_t> visible_;
  std::vector<double> latencies_ms_;
  uint64_t serial_ = 0;
  uint64_t cycles_ = 0;
  uint64_t last_cycle_sent_ = 0;
  uint64_t load_bytes_ = 0;
  // Seed 000 §3.4: s and b for each cycle from the measured frame latencies (docs/controller.md).
  std::unique_ptr<AdaptiveController> controller_;
  double sum_load_mb_ = 0, sum_bias_ = 0, sum_tw_ms_ = 0;  // per-frame sums for the run summary
  uint64_t load_time_limited_frames_ = 0;
};

Status Renderer::set_up() {
  output_dir_ = cfg_.render.output_dir;
  std::error_code ec;
  fs::create_directories(output_dir_ / "frames", ec);
  if (ec) return make_error(ErrorCode::kIo, "render.output_dir '" + output_dir_.string() + "': " + ec.message());

  auto scene = SceneData::load(cfg_.scene.dir);
  if (!scene) return scene.error();
  scene_ = std::move(*scene);
  const fs::path path_file = cfg_.render.camera_path.empty() ? scene_.dir / scene_.manifest.camera_path
                                                             : fs::path(cfg_.render.camera_path);
  auto path = CameraPath::load(path_file);
  if (!path) return path.error();
  if (path->keys().empty()) return make_error(ErrorCode::kInvalidArgument, path_file.string() + ": no keyframes");
  path_ = std::make_unique<CameraPath>(std::move(*path));

  // cache.format = auto takes the scene's texel format; an explicit one must match the scene's textures.
  const auto format = cfg_.cache.format == "auto" ? std::optional<TexelFormat>(scene_.manifest.texture_format)
                                                  : texel_format_from_string(cfg_.cache.format);
  if (!format) {
    return make_error(ErrorCode::kInvalidArgument, "cache.format: '" + cfg_.cache.format + "' is not auto, rgba8 or bc1");
  }
  VulkanContextOptions vo;
  vo.device_substring = cfg_.render.device;
  vo.validation = cfg_.render.validation;
  vo.need_bc1 = *format == TexelFormat::kBc1;
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

  states_ = std::make_unique<TextureStates>(scene_.shapes());
  TextureCacheOptions co;
  co.format = *format;
  co.layer_extent = static_cast<uint32_t>(cfg_.cache.layer_extent_px);
  co.layers = static_cast<uint32_t>(cfg_.cache.layers);
  co.staging_bytes = static_cast<uint64_t>(cfg_.render.staging_bytes);
  co.memory_bytes = static_cast<uint64_t>(cfg_.cache.memory_bytes);
  auto cache = TextureCache::create(*ctx_, co, scene_, *states_);
  if (!cache) return cache.error();
  cache_ = std::move(*cache);
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
  compiler_ = std::make_unique<ShaderCompiler>(ShaderCompiler::default_source_dir(), ShaderCompiler::default_cache_dir());
  ScenePassesOptions po;
  po.width = static_cast<uint32_t>(cfg_.render.width_px);
  po.height = static_cast<uint32_t>(cfg_.render.height_px);
  po.wide_width = std::max(16u, po.width / kWidePassDivisor);
  po.wide_height = std::max(16u, po.height / kWidePassDivisor);
  auto view = debug_view_from_string(cfg_.render.debug_view);
  if (!view) return view.error();
  po.debug_view = *view;
  auto passes = ScenePasses::create(*ctx_, *compiler_, po, *scene_gpu_, *cache_);
  if (!passes) return passes.error();
  passes_ = std::move(*passes);
  if (interactive_) TS_TRY(interactive_->attach(*ctx_));
  auto capture = FrameCapture::create(*ctx_, po.width, po.height);
  if (!capture) return capture.error();
  capture_ = std::make_unique<FrameCapture>(std::move(*capture));
  broad_phase_ = std::make_unique<BroadPhase>(scene_.meshes.meshes);

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

  auto client = StreamClient::start(cfg_, scene_.shapes(), scene_.dir, run_.config_file, run_.overrides);
  if (!client) return client.error();
  client_ = std::move(*client);
  return ok_status();
}

Status Renderer::render_frame(uint64_t index, bool last) {
  const auto t0 = Clock::now();
  const double time_s = static_cast<double>(index) * cfg_.render.frame_time_ms / 1000.0;
  CameraLens lens{cfg_.render.fov_y_deg, cfg_.render.offscreen_fov_y_deg,
                  static_cast<double>(cfg_.render.width_px) / static_cast<double>(cfg_.render.height_px),
                  cfg_.render.near_m, cfg_.render.far_m};
  const Camera cam = make_camera(interactive_ ? interactive_->next_pose() : path_->sample(time_s), lens);

  // Broad phase over the wide frustum: the wide pass needs those meshes too.
  broad_phase_->query(Frustum::from_matrix(cam.wide_proj * cam.view), cam.position, visible_);
  FrameRecording rec;
  rec.draw_count = scene_gpu_->write_draws(scene_, visible_, cam.position);
  rec.main = main_pass_constants(cam);
  const auto& po = passes_->options();
  rec.wide = wide_pass_constants(cam, cfg_.render.fov_y_deg, cfg_.render.offscreen_fov_y_deg, po.height,
                                 po.wide_height);
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
  } else {
    LoadTimeSink timed(*cache_, Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                                   std::chrono::duration<double, std::milli>(cfg_.controller.load_time_ms)));
    client_->poll(timed, static_cast<size_t>(cfg_.stream.max_mips_per_cycle));
    if (timed.limited()) ++load_time_limited_frames_;
  }
  const uint64_t in_flight = client_->stats().in_flight;
  rec.feedback = cfg_.render.feedback;  // off: no metadata, so no streaming cycle either
  rec.read_back_list = rec.feedback && static_cast<double>(in_flight) <=
                                           kCycleOutstandingFraction * static_cast<double>(last_cycle_sent_);
  const bool write = last || (cfg_.render.write_every_frames > 0 &&
                              index % static_cast<uint64_t>(cfg_.render.write_every_frames) == 0);

  VkDevice device = ctx_->device();
  ++serial_;
  TS_VK_TRY(vkResetCommandBuffer(cmd_, 0));
  VkCommandBufferBeginInfo bi{};
  bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
  bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  TS_VK_TRY(vkBeginCommandBuffer(cmd_, &bi));
  TS_TRY(cache_->prepare_uploads(serial_));  // this frame's sparse binds: one vkQueueBindSparse
  cache_->record_uploads(cmd_, serial_);
  passes_->record(cmd_, rec);
  if (write) capture_->record(cmd_, passes_->colour().handle());
  TS_VK_TRY(vkEndCommandBuffer(cmd_));
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
  VkFence fence = fence_.get();
  TS_VK_TRY(vkResetFences(device, 1, &fence));
  TS_VK_TRY(vkQueueSubmit(ctx_->queue(), 1, &si, fence));
  TS_VK_TRY(vkWaitForFences(device, 1, &fence, VK_TRUE, UINT64_MAX));
  cache_->on_submission_complete(serial_);
  if (interactive_) {
    InteractiveReadout r;
    r.frame_latency_ms = latencies_ms_.empty() ? 0.0 : latencies_ms_.back();
    r.bytes_uploaded_total = cache_->stats().bytes_uploaded;
    r.textures_resident = cache_->resident_textures();
    r.texture_count = scene_.textures.size();
    r.load_size_mb = static_cast<double>(load_bytes_) / 1e6;
    TS_TRY(interactive_->present(passes_->colour().handle(), passes_->options().width, passes_->options().height, r));
  }
  if (rec.read_back_list) start_cycle();
  // Lock-step waits for the server are not frame latency: they would not exist in real time.
  latencies_ms_.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0 - waited).count());
  // Δt of Eq. 4-7 is in seconds; the next cycle uses the s and b this frame leads to.
  controller_->on_frame(latencies_ms_.back() / 1e3);
  sum_load_mb_ += controller_->load_size_bytes() / 1e6;
  sum_bias_ += controller_->mip_bias();
  sum_tw_ms_ += controller_->weighted_latency_s() * 1e3;

  if (write) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05llu.png", static_cast<unsigned long long>(index));
    TS_TRY(capture_->write_png(output_dir_ / "frames" / name));
  }
  return ok_status();
}

void Renderer::start_cycle() {
  const auto* header = scene_gpu_->readback.as<gpu::CompactListHeader>();
  const uint32_t count = std::min(header->count, scene_gpu_->compact_capacity);
  const auto* entries = reinterpret_cast<const gpu::CompactEntry*>(scene_gpu_->readback.bytes().data() +
                                                                   sizeof(gpu::CompactListHeader));
  uint64_t skipped = 0;
  const auto candidates = build_candidates({entries, count}, scene_.meshes.meshes, &skipped);
  if (skipped) spdlog::warn("visibility list: {} entries with a bad mesh id skipped", skipped);

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
  for (uint64_t i = 0; i < frames && !(interactive_ && interactive_->closed()); ++i, ++rendered)
    TS_TRY(render_frame(i, i + 1 == frames));
  frames = rendered;
  if (interactive_) TS_TRY(interactive_->finish());
  TS_VK_TRY(vkDeviceWaitIdle(ctx_->device()));

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
  s.texture_count = scene_.textures.size();
  s.streaming_cycles = cycles_;
  s.evictions = cache_->stats().evictions;
  s.controller_mode = to_string(controller_->params().mode);
  const double n = frames ? static_cast<double>(frames) : 1.0;
  s.avg_load_size_mb = sum_load_mb_ / n;
  s.avg_mip_bias = sum_bias_ / n;
  s.avg_weighted_latency_ms = sum_tw_ms_ / n;
  s.load_time_limited_frames = load_time_limited_frames_;
  s.controller_rejected_frames = controller_->frames_rejected();
  TS_TRY(cache_->write_stats_json(output_dir_ / "cache.json"));  // budget checks, binds, thrash rate
  // Shut the server down and release the device before the validation counts are read: teardown is validated too.
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
