#include "texstream/render/frame/render_stack.hpp"

#include <algorithm>
#include <chrono>

#include "texstream/render/frame/frame_capture.hpp"
#include "texstream/render/scene/scene_data.hpp"
#include "texstream/render/vulkan/shader_compiler.hpp"
#include "texstream/render/vulkan/vk_check.hpp"

namespace texstream::render {

Result<ScenePassesOptions> scene_passes_options(const Config& cfg) {
  ScenePassesOptions po;
  po.width = static_cast<uint32_t>(cfg.render.width_px);
  po.height = static_cast<uint32_t>(cfg.render.height_px);
  po.wide_width = std::max(16u, po.width / kWidePassDivisor);
  po.wide_height = std::max(16u, po.height / kWidePassDivisor);
  po.debug_view = gpu_debug_view(cfg.render.debug_view);
  return po;
}

RenderStack::RenderStack(const SceneData& scene) : scene_(scene) {}

RenderStack::~RenderStack() {
  if (ctx_) vkDeviceWaitIdle(ctx_->device());  // nothing to do about a failure here
}

Result<std::unique_ptr<RenderStack>> RenderStack::create(const SceneData& scene, const RenderStackOptions& options) {
  std::unique_ptr<RenderStack> s(new RenderStack(scene));
  auto stage = [&](const char* name) {
    if (options.stage) options.stage(name);
  };
  auto ctx = VulkanContext::create(options.vulkan);
  if (!ctx) return ctx.error();
  s->ctx_ = std::move(*ctx);
  stage("vulkan");

  auto cache = TextureCache::create(*s->ctx_, options.cache, scene);
  if (!cache) return cache.error();
  s->cache_ = std::move(*cache);
  stage("texture_cache");

  if (options.ground && scene.ground_pages) {
    auto ground = GroundPages::create(*s->ctx_, scene.ground_pages, *scene.manifest.ground, *options.ground);
    if (!ground) return ground.error();
    s->ground_ = std::move(*ground);
    stage("ground_pages");
  }

  auto gpu = SceneGpu::create(*s->ctx_, scene, options.stage_geometry);
  if (!gpu) return gpu.error();
  s->scene_gpu_ = std::make_unique<SceneGpu>(std::move(*gpu));
  stage("scene_gpu_upload");

  s->compiler_ =
      std::make_unique<ShaderCompiler>(ShaderCompiler::default_source_dir(), ShaderCompiler::default_cache_dir());
  ScenePassesOptions pass_options = options.passes;
  pass_options.alpha_test = scene.has_alpha_test();
  auto passes =
      ScenePasses::create(*s->ctx_, *s->compiler_, pass_options, *s->scene_gpu_, *s->cache_, s->ground_.get());
  if (!passes) return passes.error();
  s->passes_ = std::move(*passes);
  stage("passes_and_shaders");

  auto capture = FrameCapture::create(*s->ctx_, options.passes.width, options.passes.height);
  if (!capture) return capture.error();
  s->capture_ = std::make_unique<FrameCapture>(std::move(*capture));
  s->broad_phase_ = BroadPhase::for_scene(scene);  // mesh_index.bin, mapped (built and kept once when missing)
  stage("broad_phase_tree");

  VkDevice device = s->ctx_->device();
  VkCommandPoolCreateInfo pci{};
  pci.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
  pci.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pci.queueFamilyIndex = s->ctx_->queue_family();
  VkCommandPool pool = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateCommandPool(device, &pci, nullptr, &pool));
  s->pool_ = UniqueCommandPool(device, pool);
  VkCommandBufferAllocateInfo ai{};
  ai.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
  ai.commandPool = pool;
  ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  ai.commandBufferCount = 1;
  TS_VK_TRY(vkAllocateCommandBuffers(device, &ai, &s->cmd_));
  VkFenceCreateInfo fci{};
  fci.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
  VkFence fence = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateFence(device, &fci, nullptr, &fence));
  s->fence_ = UniqueFence(device, fence);
  return s;
}

Status RenderStack::submit(const Submission& s) {
  auto step = [&](const char* name) {
    if (s.step) s.step(name);
  };
  using Clock = std::chrono::steady_clock;
  const auto ms_since = [](Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
  };
  const auto begin = Clock::now();
  double bind_ms = 0;
  ++serial_;
  TS_VK_TRY(vkResetCommandBuffer(cmd_, 0));
  VkCommandBufferBeginInfo bi{};
  bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
  bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  TS_VK_TRY(vkBeginCommandBuffer(cmd_, &bi));
  if (s.uploads == Uploads::kAll || s.uploads == Uploads::kMips) {
    const auto bind_start = Clock::now();
    TS_TRY(cache_->prepare_uploads(serial_));  // this frame's sparse binds: one vkQueueBindSparse
    bind_ms = ms_since(bind_start);
    cache_->record_uploads(cmd_, serial_);
    if (ground_) ground_->record_uploads(cmd_);
  }
  if (s.uploads == Uploads::kAll || s.uploads == Uploads::kGeometry) TS_TRY(scene_gpu_->record_uploads(scene_, cmd_));
  step("record_uploads");
  // Every submission is waited for below and nothing recorded so far binds the passes' descriptor set, so it may
  // change now: the cache may have grown its texture table into a new buffer since the last submission
  // (TextureCache::write_slots, commit).
  passes_->bind_texture_table(cache_->texture_table());
  if (s.passes) passes_->record(cmd_, *s.passes);
  if (s.capture) capture_->record(cmd_, passes_->colour().handle());
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
  VkDevice device = ctx_->device();
  VkFence fence = fence_.get();
  TS_VK_TRY(vkResetFences(device, 1, &fence));
  const auto t0 = Clock::now();
  const double record_ms = std::chrono::duration<double, std::milli>(t0 - begin).count() - bind_ms;
  TS_VK_TRY(vkQueueSubmit(ctx_->queue(), 1, &si, fence));
  TS_VK_TRY(vkWaitForFences(device, 1, &fence, VK_TRUE, UINT64_MAX));
  last_times_ = SubmitTimes{bind_ms, record_ms, ms_since(t0)};
  cache_->on_submission_complete(serial_);
  if (ground_) ground_->on_submission_complete(s.passes != nullptr);
  step("gpu");
  return ok_status();
}

Status RenderStack::tear_down() {
  TS_VK_TRY(vkDeviceWaitIdle(ctx_->device()));
  passes_.reset();
  capture_.reset();
  scene_gpu_.reset();
  cache_.reset();
  ground_.reset();
  fence_.reset();
  pool_.reset();
  broad_phase_.reset();
  compiler_.reset();
  return ok_status();
}

}  // namespace texstream::render
