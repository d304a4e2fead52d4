#pragma once
// Everything one frame records on the GPU, in order:
//   1. the main pass: colour (R8G8B8A8_SRGB) + reversed-Z depth, every visible mesh in one indirect draw,
//      shading from the cache / colormap and writing visibility metadata (scene.frag);
//   2. the wide pass: a small depth-only render at the off-screen FOV whose fragments outside the viewport
//      add metadata at W = 1 per viewport pixel (scene.frag with WIDE_PASS; seed 000 §3.2);
//   3. compaction of the metadata (compact.comp, seed 000 §3.3), and, only when a streaming cycle is about
//      to start, a copy of the compacted list to host memory.
// One descriptor set and one pipeline layout serve all three pipelines.
#include <vulkan/vulkan.h>

#include <memory>

#include "texstream/common/result.hpp"
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
};

struct FrameRecording {
  uint32_t draw_count = 0;
  gpu::PassConstants main{};
  gpu::PassConstants wide{};
  bool read_back_list = false;  // copy the compacted list to SceneGpu::readback
};

class ScenePasses {
 public:
  static Result<std::unique_ptr<ScenePasses>> create(const VulkanContext& ctx, ShaderCompiler& compiler,
                                                     const ScenePassesOptions& options, const SceneGpu& scene,
                                                     const TextureCache& cache);
  void record(VkCommandBuffer cmd, const FrameRecording& frame) const;

  const GpuImage& colour() const { return colour_; }  // TRANSFER_SRC_OPTIMAL after record()
  const ScenePassesOptions& options() const { return options_; }

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
  UniqueDescriptorSetLayout set_layout_;
  UniqueDescriptorPool pool_;
  VkDescriptorSet set_ = VK_NULL_HANDLE;  // freed with the pool
  UniquePipelineLayout layout_;
  UniquePipeline main_pipeline_;
  UniquePipeline wide_pipeline_;
  UniquePipeline compact_pipeline_;
};

}  // namespace texstream::render
