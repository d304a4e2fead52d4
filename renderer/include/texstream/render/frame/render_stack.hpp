#pragma once
// The render stack: the objects every renderer variant draws with, made in one order and destroyed in the
// reverse — the Vulkan context, the texture cache, the scene's GPU buffers, the shader compiler, the scene
// passes, the frame capture, the broad phase, and one command buffer with its fence. The frame loop (app/
// Renderer) streams into it; ViewRenderer draws single views with it. Both plan their frames with
// plan_frame() (frame_plan.hpp) and draw them with submit().
//
// One submission at a time: submit() waits for its fence, so the next frame may reuse every host-visible
// buffer (draw lists, staging) at once.
#include <vulkan/vulkan.h>

#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"
#include "texstream/render/cache/ground_pages.hpp"
#include "texstream/render/cache/texture_cache.hpp"
#include "texstream/render/frame/scene_passes.hpp"
#include "texstream/render/scene/broad_phase.hpp"
#include "texstream/render/scene/frame_recording.hpp"
#include "texstream/render/scene/scene_gpu.hpp"
#include "texstream/render/vulkan/vk_handle.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

namespace texstream::render {

class FrameCapture;
class ShaderCompiler;
struct SceneData;

// Called with the name of each step as it ends (start-up stages, frame 0's parts); may be empty.
using StepHook = std::function<void(const char* name)>;

struct RenderStackOptions {
  VulkanContextOptions vulkan;
  TextureCacheOptions cache;
  ScenePassesOptions passes;
  bool stage_geometry = false;  // SceneGpu copies meshes through staging even on unified memory (tests)
  // The ground's pages (GroundPages) when the scene has a ground; nullopt: the ground is not drawn.
  std::optional<GroundPagesOptions> ground;
  // After each part: "vulkan", "texture_cache", "scene_gpu_upload", "passes_and_shaders", "broad_phase_tree"
  // (RunSummary::startup_seconds).
  StepHook stage;
};

// What a submission uploads before its passes: everything committed so far (the texture cache's mips and
// the meshes made resident), only the mips, only the meshes' geometry, or nothing.
enum class Uploads { kAll, kMips, kGeometry, kNone };

struct Submission {
  const FrameRecording* passes = nullptr;  // the frame's passes; null: uploads only
  Uploads uploads = Uploads::kAll;
  bool capture = false;  // copy the colour target to the host (FrameCapture)
  // "record_uploads" once the uploads are recorded, "gpu" once the fence has signalled (frame 0's parts).
  StepHook step;
};

// The passes' size and debug view from render.width_px, height_px and debug_view; the wide metadata pass at
// 1/kWidePassDivisor of the viewport per axis (it only ranks off-screen meshes). Errors name the key.
inline constexpr uint32_t kWidePassDivisor = 4;
Result<ScenePassesOptions> scene_passes_options(const Config& cfg);

class RenderStack {
 public:
  // `scene` must outlive the stack.
  static Result<std::unique_ptr<RenderStack>> create(const SceneData& scene, const RenderStackOptions& options);
  ~RenderStack();
  RenderStack(const RenderStack&) = delete;
  RenderStack& operator=(const RenderStack&) = delete;

  // Records `s` into the command buffer, submits it after the cache's sparse binds, waits for it and
  // publishes its uploads (TextureCache::on_submission_complete).
  Status submit(const Submission& s);
  // Where the last submit() spent its time, in milliseconds (frames.csv bind_ms, record_ms, gpu_ms).
  struct SubmitTimes {
    double bind_ms = 0;    // the cache's page binds (prepare_uploads)
    double record_ms = 0;  // the rest of the recording
    double gpu_ms = 0;     // submit to fence
  };
  const SubmitTimes& last_times() const { return last_times_; }
  double last_gpu_ms() const { return last_times_.gpu_ms; }
  // Waits for the device and destroys everything but the context, so that its validation counts include the
  // teardown. Only context() may be used afterwards.
  Status tear_down();

  const SceneData& scene() const { return scene_; }
  VulkanContext& context() { return *ctx_; }
  const VulkanContext& context() const { return *ctx_; }
  TextureCache& cache() { return *cache_; }
  // Null when the scene has no ground or it is not drawn (pages.enabled = false).
  GroundPages* ground() { return ground_.get(); }
  const GroundPages* ground() const { return ground_.get(); }
  const TextureCache& cache() const { return *cache_; }
  SceneGpu& scene_gpu() { return *scene_gpu_; }
  const SceneGpu& scene_gpu() const { return *scene_gpu_; }
  ScenePasses& passes() { return *passes_; }
  const ScenePasses& passes() const { return *passes_; }
  FrameCapture& capture() { return *capture_; }
  BroadPhase& broad_phase() { return *broad_phase_; }

  // The frame plan's lists (frame_plan.hpp), kept here so that their memory is reused frame after frame:
  // the meshes the last frame drew, and the textures of those drawn for the first time.
  std::vector<uint32_t>& visible() { return visible_; }
  const std::vector<uint32_t>& visible() const { return visible_; }
  std::vector<uint32_t>& new_textures() { return new_textures_; }

 private:
  explicit RenderStack(const SceneData& scene);

  const SceneData& scene_;
  std::unique_ptr<VulkanContext> ctx_;
  std::unique_ptr<TextureCache> cache_;
  std::unique_ptr<GroundPages> ground_;
  std::unique_ptr<SceneGpu> scene_gpu_;
  std::unique_ptr<ShaderCompiler> compiler_;
  std::unique_ptr<ScenePasses> passes_;
  std::unique_ptr<FrameCapture> capture_;
  std::unique_ptr<BroadPhase> broad_phase_;
  UniqueCommandPool pool_;
  VkCommandBuffer cmd_ = VK_NULL_HANDLE;
  UniqueFence fence_;
  uint64_t serial_ = 0;  // submissions so far: the cache publishes by it
  SubmitTimes last_times_;
  std::vector<uint32_t> visible_;
  std::vector<uint32_t> new_textures_;
};

}  // namespace texstream::render
