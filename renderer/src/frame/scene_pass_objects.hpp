#pragma once
// The Vulkan objects ScenePasses is built from — render passes, framebuffers, shader modules, barriers — and
// their formats: kept apart from scene_passes.cpp, which composes them into the frame's passes.
#include <vulkan/vulkan.h>

#include <span>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/render/vulkan/shader_compiler.hpp"
#include "texstream/render/vulkan/vk_handle.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

namespace texstream::render::pass_objects {

constexpr VkFormat kColourFormat = VK_FORMAT_R8G8B8A8_SRGB;
// Debug views write raw bytes (grey levels, heat colours, hashed ids) that a PNG must carry unchanged.
constexpr VkFormat kDebugColourFormat = VK_FORMAT_R8G8B8A8_UNORM;
// Reversed-Z wants float depth: precision is then nearly uniform in log-distance over near..far = 1..20000 m.
constexpr VkFormat kDepthFormat = VK_FORMAT_D32_SFLOAT;
// The pre-pass's id buffer: mesh id + 1 per pixel (0 = no mesh); 32 bits hold any mesh count.
constexpr VkFormat kOwnerFormat = VK_FORMAT_R32_UINT;
// The shading subpass's per-pixel mesh and metadata (layout: gpu::kMetaMipShift in shared_structs.h).
constexpr VkFormat kMetaFormat = VK_FORMAT_R32G32_UINT;

constexpr VkShaderStageFlags kAllStages =
    VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT | VK_SHADER_STAGE_COMPUTE_BIT;

Result<UniqueShaderModule> make_module(const VulkanContext& ctx, ShaderCompiler& compiler, const ShaderRequest& req);
VkAttachmentDescription attachment(VkFormat format, VkAttachmentStoreOp store, VkImageLayout final_layout);
Result<UniqueRenderPass> finish_render_pass(VkDevice device, std::span<const VkAttachmentDescription> atts,
                                            std::span<const VkSubpassDescription> subs,
                                            std::span<const VkSubpassDependency> deps);
Result<UniqueRenderPass> make_main_pass(VkDevice device, VkFormat colour_format);
Result<UniqueRenderPass> make_wide_pass(VkDevice device);
Result<UniqueFramebuffer> make_framebuffer(VkDevice device, VkRenderPass pass, std::vector<VkImageView> views,
                                           uint32_t w, uint32_t h);
// A descriptor set layout of `bindings`, a pool sized for exactly one set of it (counts summed per type from the
// bindings), and that set (freed with the pool).
struct SingleSet {
  UniqueDescriptorSetLayout layout;
  UniqueDescriptorPool pool;
  VkDescriptorSet set = VK_NULL_HANDLE;
};
Result<SingleSet> make_single_set(VkDevice device, std::span<const VkDescriptorSetLayoutBinding> bindings);
// A pipeline layout of `sets` in order, with the passes' push constants (gpu::PassConstants, every stage).
Result<UniquePipelineLayout> make_pipeline_layout(VkDevice device, std::span<const VkDescriptorSetLayout> sets);
void memory_barrier(VkCommandBuffer cmd, VkPipelineStageFlags src_stage, VkAccessFlags src,
                    VkPipelineStageFlags dst_stage, VkAccessFlags dst);

}  // namespace texstream::render::pass_objects
