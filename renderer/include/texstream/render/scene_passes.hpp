#pragma once
// Everything one frame records on the GPU, in order:
//   1. the main pass: colour (R8G8B8A8_SRGB; UNORM for debug views) + reversed-Z depth. A depth-only pre-pass
//      draws every mesh the broad phase kept (one multi-draw indirect), then the shading draw (the same
//      indirect list) runs with an EQUAL depth test and no depth writes, so only the fragments that end up
//      visible shade and write visibility metadata (scene.frag): a mesh hidden behind a later-drawn one gets
//      none, whatever the draw order;
//   2. the wide pass: a small depth-only render at the off-screen FOV whose fragments outside the viewport
//      add metadata at W = 1 per viewport pixel (scene.frag with WIDE_PASS; seed 000 §3.2);
//   3. compaction of the metadata (compact.comp, seed 000 §3.3), and, only when a streaming cycle is about
//      to start, a copy of the used prefix of the compacted list to host memory (compact_args.comp computes
//      the indirect dispatch of compact_copy.comp from the final count).
// With feedback off (render.feedback = false, or FrameRecording::feedback) steps 2 and 3 and the metadata
// writes are skipped: the same frame without visibility, to measure what visibility costs.
// One descriptor set and one pipeline layout serve every pipeline.
#include <vulkan/vulkan.h>

#include <memory>
#include <string>

#include "texstream/common/result.hpp"
#include "texstream/render/gpu_buffer.hpp"
#include "texstream/render/gpu_image.hpp"
#include "texstream/render/gpu_structs.hpp"
#include "texstream/render/vk_handle.hpp"

namespace texstream::render {

class VulkanContext;
class ShaderCompiler;
class TextureCache;
struct SceneGpu;

struct ScenePassesOptions {
  uint32_t width = 960;
  uint32_t height = 540;
  uint32_t wide_width = 240;   // the wide pass only feeds metadata: a quarter of the viewport per axis
  uint32_t wide_height = 135;
  uint32_t debug_view = 0;     // gpu::kDebugView*; any other than none renders into a UNORM target
  bool lod_probe = false;      // main pass compiled with LOD_PROBE: per-pixel metadata level vs textureQueryLod
  float probe_anisotropy = 16; // A_m of the probe sampler (clamped to the device's maxSamplerAnisotropy)
};

// Parses render.debug_view (none, mip, weight, mesh_id) into gpu::kDebugView*.
Result<uint32_t> debug_view_from_string(const std::string& name);

struct FrameRecording {
  uint32_t draw_count = 0;
  gpu::PassConstants main{};
  gpu::PassConstants wide{};
  bool read_back_list = false;  // copy the used prefix of the compacted list to SceneGpu::readback
  bool feedback = true;         // metadata writes, wide pass, compaction (false: only the picture)
};

class ScenePasses {
 public:
  static Result<std::unique_ptr<ScenePasses>> create(const VulkanContext& ctx, ShaderCompiler& compiler,
                                                     const ScenePassesOptions& options, const SceneGpu& scene,
                                                     const TextureCache& cache);
  void record(VkCommandBuffer cmd, const FrameRecording& frame) const;

  const GpuImage& colour() const { return colour_; }  // TRANSFER_SRC_OPTIMAL after record()
  VkFormat colour_format() const;
  const ScenePassesOptions& options() const { return options_; }
  // LOD_PROBE only: gpu::LodProbeSample per viewport pixel (host-visible; zero it before a probed frame).
  const GpuBuffer& probe() const { return probe_; }
  // Whether the probe sampler really filters anisotropically (the device's samplerAnisotropy feature).
  bool probe_is_anisotropic() const { return probe_anisotropic_; }

 private:
  ScenePasses(const ScenePassesOptions& options, const SceneGpu& scene) : options_(options), scene_(scene) {}
  Status create_targets(const VulkanContext& ctx);
  Status create_descriptors(const VulkanContext& ctx, const TextureCache& cache);
  Status create_pipelines(const VulkanContext& ctx, ShaderCompiler& compiler);

  ScenePassesOptions options_;
  const SceneGpu& scene_;
  GpuImage colour_;
  GpuImage depth_;
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
  VkDescriptorSet set_ = VK_NULL_HANDLE;  // freed with the pool
  UniquePipelineLayout layout_;
  UniquePipeline prepass_pipeline_;
  UniquePipeline main_pipeline_;
  UniquePipeline wide_pipeline_;
  UniquePipeline compact_pipeline_;
  UniquePipeline compact_args_pipeline_;
  UniquePipeline compact_copy_pipeline_;
};

}  // namespace texstream::render
