#pragma once
// Everything one frame records on the GPU, in order:
//   1. the main pass: colour (R8G8B8A8_SRGB; UNORM for debug views) + reversed-Z depth. Subpass 0, the
//      pre-pass, draws the meshes in the viewport's frustum (one multi-draw indirect) writing depth and the
//      pixel's owner (mesh id + 1, R32_UINT, prepass.frag); subpass 1 draws the same list with an EQUAL depth
//      test and no depth writes, and only the owner's fragment shades and writes visibility metadata
//      (scene.frag): a mesh hidden behind a later-drawn one gets none, whatever the draw order, and of two
//      coplanar surfaces only the first drawn counts (the one the id view shows);
//   2. the wide pass: a small depth-only render at the off-screen FOV whose fragments outside the viewport
//      add metadata at W = 1 per viewport pixel (scene.frag with WIDE_PASS; seed 000 §3.2). It draws only the
//      meshes that reach outside the viewport's frustum (FrameRecording::wide_first): a mesh inside it has no
//      fragment outside the viewport, so it can neither add metadata there nor hide a mesh there;
//   3. compaction of the metadata (compact.comp, seed 000 §3.3): one invocation per mesh drawn this frame (the
//      only meshes that can have metadata), so its cost follows the view, not the scene. When a streaming
//      cycle is about to start (FrameRecording::read_back_list) it compacts straight into the host-visible
//      read-back list, so only the used prefix crosses to the host, in the same dispatch.
// With feedback off (render.feedback = false, or FrameRecording::feedback) steps 2 and 3 and the metadata
// writes are skipped: the same frame without visibility, to measure what visibility costs.
// One descriptor set and one pipeline layout serve every pipeline.
#include <vulkan/vulkan.h>

#include <memory>
#include <string>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"
#include "texstream/render/scene/frame_recording.hpp"
#include "texstream/render/scene/gpu_structs.hpp"
#include "texstream/render/vulkan/gpu_buffer.hpp"
#include "texstream/render/vulkan/gpu_image.hpp"
#include "texstream/render/vulkan/vk_handle.hpp"

namespace texstream::render {

class VulkanContext;
class ShaderCompiler;
class TextureCache;
class SceneGpu;
class GroundPages;

struct ScenePassesOptions {
  uint32_t width = 960;
  uint32_t height = 540;
  uint32_t wide_width = 240;  // the wide pass only feeds metadata: a quarter of the viewport per axis
  uint32_t wide_height = 135;
  uint32_t debug_view = 0;      // gpu::kDebugView*; any other than none renders into a UNORM target
  bool alpha_test = false;      // the depth pre-pass samples the cache and discards cut-out texels (prepass.frag)
  bool lod_probe = false;       // main pass compiled with LOD_PROBE: per-pixel metadata level vs textureQueryLod
  float probe_anisotropy = 16;  // A_m of the probe sampler (clamped to the device's maxSamplerAnisotropy)
  bool timestamps = false;      // GPU timestamps around the passes (read_pass_times)
  // The wide pass's atomics combined per subgroup first (scene.frag SUBGROUP_FEEDBACK) where the device has
  // fragment-stage subgroup arithmetic and ballot; false: one atomic pair per fragment.
  bool subgroup_reduce = true;
};

// GPU time of the passes of the last recorded frame (ScenePassesOptions::timestamps; zeros otherwise).
struct PassTimes {
  double main_ms = 0;     // pre-pass + shading subpass (with the metadata writes when feedback is on)
  double wide_ms = 0;     // the wide pass
  double compact_ms = 0;  // compaction and, when asked, the prefix copy for the read-back
};

using UniqueQueryPool = DeviceHandle<VkQueryPool, vkDestroyQueryPool>;

// render.debug_view as the shaders' gpu::kDebugView* constant.
uint32_t gpu_debug_view(DebugView view);

class ScenePasses {
 public:
  static Result<std::unique_ptr<ScenePasses>> create(const VulkanContext& ctx, ShaderCompiler& compiler,
                                                     const ScenePassesOptions& options, const SceneGpu& scene,
                                                     const TextureCache& cache, const GroundPages* ground = nullptr);
  void record(VkCommandBuffer cmd, const FrameRecording& frame) const;
  // Points the texture table's binding at `table` when the cache has grown it into a new buffer
  // (TextureCache::texture_table()). Between submissions only: no recorded or pending command buffer may use the
  // descriptor set (RenderStack::submit calls it before recording, after the last submission's fence).
  void bind_texture_table(VkBuffer table);
  // After the recorded frame's submission completed.
  PassTimes read_pass_times() const;

  const GpuImage& colour() const { return colour_; }  // TRANSFER_SRC_OPTIMAL after record()
  VkFormat colour_format() const;
  const ScenePassesOptions& options() const { return options_; }
  // LOD_PROBE only: gpu::LodProbeSample per viewport pixel (host-visible; zero it before a probed frame).
  const GpuBuffer& probe() const { return probe_; }
  // Whether the probe sampler really filters anisotropically (the device's samplerAnisotropy feature).
  bool probe_is_anisotropic() const { return probe_anisotropic_; }

 private:
  static constexpr uint32_t kTimestampCount = 4;  // start, after main, after wide, after reduce + compaction

  ScenePasses(const ScenePassesOptions& options, const SceneGpu& scene) : options_(options), scene_(scene) {}
  Status create_targets(const VulkanContext& ctx);
  Status create_descriptors(const VulkanContext& ctx, const TextureCache& cache);
  Status create_pipelines(const VulkanContext& ctx, ShaderCompiler& compiler);
  Status create_ground_descriptors(const VulkanContext& ctx);

  ScenePassesOptions options_;
  const SceneGpu& scene_;
  VkDevice device_ = VK_NULL_HANDLE;
  UniqueQueryPool timestamps_;
  double timestamp_period_ns_ = 1;
  mutable uint32_t timestamps_written_ = 0;  // by the last record(): 2 without feedback, 4 with
  GpuImage colour_;
  GpuImage depth_;
  GpuImage owner_;  // the pre-pass's id buffer (input attachment of the shading subpass)
  GpuImage meta_;   // the shading subpass's per-pixel mesh and metadata, read by meta_reduce
  GpuImage wide_depth_;
  UniqueRenderPass main_pass_;
  UniqueRenderPass wide_pass_;
  UniqueFramebuffer main_fb_;
  UniqueFramebuffer wide_fb_;
  UniqueSampler sampler_;
  UniqueSampler probe_sampler_;
  GpuBuffer probe_;
  bool probe_anisotropic_ = false;
  UniqueDescriptorSetLayout set_layout_;
  UniqueDescriptorPool pool_;
  VkDescriptorSet set_ = VK_NULL_HANDLE;     // freed with the pool
  VkBuffer texture_table_ = VK_NULL_HANDLE;  // what set_'s kBindingTextures names
  UniquePipelineLayout layout_;
  UniquePipeline prepass_pipeline_;
  UniquePipeline main_pipeline_;
  UniquePipeline wide_pipeline_;
  UniquePipeline meta_reduce_pipeline_;
  UniquePipeline compact_pipeline_;
  UniquePipeline compact_to_host_pipeline_;
  // The ground's pages (scene.json "ground"; null without): set 1, its layout and its two pipelines.
  const GroundPages* ground_ = nullptr;
  UniqueSampler ground_sampler_;
  UniqueDescriptorSetLayout ground_set_layout_;
  UniqueDescriptorPool ground_pool_;
  VkDescriptorSet ground_set_ = VK_NULL_HANDLE;
  UniquePipelineLayout ground_layout_;
  UniquePipeline ground_prepass_pipeline_;
  UniquePipeline ground_pipeline_;
};

}  // namespace texstream::render
