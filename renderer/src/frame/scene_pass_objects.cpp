#include "scene_pass_objects.hpp"

#include <algorithm>
#include <array>
#include <utility>

#include "texstream/render/scene/gpu_structs.hpp"
#include "texstream/render/vulkan/vk_check.hpp"

namespace texstream::render::pass_objects {

Result<UniqueShaderModule> make_module(const VulkanContext& ctx, ShaderCompiler& compiler, const ShaderRequest& req) {
  auto spirv = compiler.compile(req);
  if (!spirv) return spirv.error();
  VkShaderModuleCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO;
  ci.codeSize = spirv->size() * sizeof(uint32_t);
  ci.pCode = spirv->data();
  VkShaderModule m = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateShaderModule(ctx.device(), &ci, nullptr, &m));
  return UniqueShaderModule(ctx.device(), m);
}

VkAttachmentDescription attachment(VkFormat format, VkAttachmentStoreOp store, VkImageLayout final_layout) {
  VkAttachmentDescription a{};
  a.format = format;
  a.samples = VK_SAMPLE_COUNT_1_BIT;
  a.loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
  a.storeOp = store;
  a.stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
  a.stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  a.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  a.finalLayout = final_layout;
  return a;
}

Result<UniqueRenderPass> finish_render_pass(VkDevice device, std::span<const VkAttachmentDescription> atts,
                                            std::span<const VkSubpassDescription> subs,
                                            std::span<const VkSubpassDependency> deps) {
  VkRenderPassCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO;
  ci.attachmentCount = static_cast<uint32_t>(atts.size());
  ci.pAttachments = atts.data();
  ci.subpassCount = static_cast<uint32_t>(subs.size());
  ci.pSubpasses = subs.data();
  ci.dependencyCount = static_cast<uint32_t>(deps.size());
  ci.pDependencies = deps.data();
  VkRenderPass rp = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateRenderPass(device, &ci, nullptr, &rp));
  return UniqueRenderPass(device, rp);
}

// The main pass: subpass 0 is the depth pre-pass, which also writes the owner id (kOwnerFormat); subpass 1
// shades with an EQUAL depth test, reads the owner id as an input attachment and writes each pixel's metadata
// (kMetaFormat) next to its colour (scene.frag). meta_reduce.comp reads the metadata after the pass.
// Attachments: 0 colour, 1 depth, 2 owner id, 3 metadata.
Result<UniqueRenderPass> make_main_pass(VkDevice device, VkFormat colour_format) {
  const std::array<VkAttachmentDescription, 4> atts{
      attachment(colour_format, VK_ATTACHMENT_STORE_OP_STORE, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL),  // captured
      attachment(kDepthFormat, VK_ATTACHMENT_STORE_OP_DONT_CARE, VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL),
      attachment(kOwnerFormat, VK_ATTACHMENT_STORE_OP_DONT_CARE, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL),
      attachment(kMetaFormat, VK_ATTACHMENT_STORE_OP_STORE, VK_IMAGE_LAYOUT_GENERAL),
  };
  const VkAttachmentReference colour_ref{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
  const VkAttachmentReference depth_ref{1, VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL};
  const VkAttachmentReference owner_out{2, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
  const VkAttachmentReference owner_in{2, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL};
  const std::array<VkAttachmentReference, 2> shading_out{
      colour_ref, VkAttachmentReference{3, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL}};
  std::array<VkSubpassDescription, 2> subs{};
  subs[0].pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
  subs[0].colorAttachmentCount = 1;
  subs[0].pColorAttachments = &owner_out;
  subs[0].pDepthStencilAttachment = &depth_ref;
  subs[1].pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
  subs[1].inputAttachmentCount = 1;
  subs[1].pInputAttachments = &owner_in;
  subs[1].colorAttachmentCount = static_cast<uint32_t>(shading_out.size());
  subs[1].pColorAttachments = shading_out.data();
  subs[1].pDepthStencilAttachment = &depth_ref;

  // In: the previous frame's use of the same attachments (its shading, capture copy and meta_reduce reads)
  // must be done before we clear. Between: the shading subpass tests against the pre-pass's depth and reads its
  // owner id at the same pixel. Out: the capture copy reads the colour, meta_reduce the metadata.
  std::array<VkSubpassDependency, 5> deps{};
  deps[0].srcSubpass = VK_SUBPASS_EXTERNAL;
  deps[0].dstSubpass = 0;
  deps[0].srcStageMask = VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT | VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT |
                         VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;
  deps[0].dstStageMask = VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT | VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[0].srcAccessMask = VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT | VK_ACCESS_INPUT_ATTACHMENT_READ_BIT;
  deps[0].dstAccessMask = VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT |
                          VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[1].srcSubpass = VK_SUBPASS_EXTERNAL;
  deps[1].dstSubpass = 1;
  deps[1].srcStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT |
                         VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;
  deps[1].dstStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[1].srcAccessMask = VK_ACCESS_TRANSFER_READ_BIT | VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[1].dstAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[2].srcSubpass = 0;
  deps[2].dstSubpass = 1;
  deps[2].srcStageMask = VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT | VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[2].dstStageMask = VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT | VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT;
  deps[2].srcAccessMask = VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT | VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[2].dstAccessMask = VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT | VK_ACCESS_INPUT_ATTACHMENT_READ_BIT;
  deps[2].dependencyFlags = VK_DEPENDENCY_BY_REGION_BIT;
  deps[3].srcSubpass = 1;
  deps[3].dstSubpass = VK_SUBPASS_EXTERNAL;
  deps[3].srcStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[3].dstStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
  deps[3].srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[3].dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT;
  deps[4].srcSubpass = 1;  // the metadata to meta_reduce
  deps[4].dstSubpass = VK_SUBPASS_EXTERNAL;
  deps[4].srcStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[4].dstStageMask = VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;
  deps[4].srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[4].dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
  return finish_render_pass(device, atts, subs, deps);
}

// The wide pass: depth only, one subpass.
Result<UniqueRenderPass> make_wide_pass(VkDevice device) {
  const std::array<VkAttachmentDescription, 1> atts{
      attachment(kDepthFormat, VK_ATTACHMENT_STORE_OP_DONT_CARE, VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL)};
  const VkAttachmentReference depth_ref{0, VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL};
  std::array<VkSubpassDescription, 1> subs{};
  subs[0].pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
  subs[0].pDepthStencilAttachment = &depth_ref;
  std::array<VkSubpassDependency, 1> deps{};
  deps[0].srcSubpass = VK_SUBPASS_EXTERNAL;
  deps[0].dstSubpass = 0;
  deps[0].srcStageMask = VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT;
  deps[0].dstStageMask = VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT;
  deps[0].srcAccessMask = VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT;
  deps[0].dstAccessMask = VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT;
  return finish_render_pass(device, atts, subs, deps);
}

Result<UniqueFramebuffer> make_framebuffer(VkDevice device, VkRenderPass pass, std::vector<VkImageView> views,
                                           uint32_t w, uint32_t h) {
  VkFramebufferCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO;
  ci.renderPass = pass;
  ci.attachmentCount = static_cast<uint32_t>(views.size());
  ci.pAttachments = views.data();
  ci.width = w;
  ci.height = h;
  ci.layers = 1;
  VkFramebuffer fb = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateFramebuffer(device, &ci, nullptr, &fb));
  return UniqueFramebuffer(device, fb);
}

void memory_barrier(VkCommandBuffer cmd, VkPipelineStageFlags src_stage, VkAccessFlags src,
                    VkPipelineStageFlags dst_stage, VkAccessFlags dst) {
  VkMemoryBarrier b{};
  b.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
  b.srcAccessMask = src;
  b.dstAccessMask = dst;
  vkCmdPipelineBarrier(cmd, src_stage, dst_stage, 0, 1, &b, 0, nullptr, 0, nullptr);
}

Result<SingleSet> make_single_set(VkDevice device, std::span<const VkDescriptorSetLayoutBinding> bindings) {
  SingleSet out;
  VkDescriptorSetLayoutCreateInfo li{};
  li.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO;
  li.bindingCount = static_cast<uint32_t>(bindings.size());
  li.pBindings = bindings.data();
  VkDescriptorSetLayout set_layout = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateDescriptorSetLayout(device, &li, nullptr, &set_layout));
  out.layout = UniqueDescriptorSetLayout(device, set_layout);
  std::vector<VkDescriptorPoolSize> sizes;
  for (const VkDescriptorSetLayoutBinding& b : bindings) {
    auto it = std::find_if(sizes.begin(), sizes.end(), [&](const auto& s) { return s.type == b.descriptorType; });
    if (it == sizes.end()) {
      sizes.push_back({b.descriptorType, b.descriptorCount});
    } else {
      it->descriptorCount += b.descriptorCount;
    }
  }
  VkDescriptorPoolCreateInfo pi{};
  pi.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO;
  pi.maxSets = 1;
  pi.poolSizeCount = static_cast<uint32_t>(sizes.size());
  pi.pPoolSizes = sizes.data();
  VkDescriptorPool pool = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateDescriptorPool(device, &pi, nullptr, &pool));
  out.pool = UniqueDescriptorPool(device, pool);
  VkDescriptorSetAllocateInfo ai{};
  ai.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO;
  ai.descriptorPool = pool;
  ai.descriptorSetCount = 1;
  ai.pSetLayouts = &set_layout;
  TS_VK_TRY(vkAllocateDescriptorSets(device, &ai, &out.set));
  return out;
}

Result<UniquePipelineLayout> make_pipeline_layout(VkDevice device, std::span<const VkDescriptorSetLayout> sets) {
  VkPushConstantRange range{kAllStages, 0, sizeof(gpu::PassConstants)};
  VkPipelineLayoutCreateInfo pli{};
  pli.sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO;
  pli.setLayoutCount = static_cast<uint32_t>(sets.size());
  pli.pSetLayouts = sets.data();
  pli.pushConstantRangeCount = 1;
  pli.pPushConstantRanges = &range;
  VkPipelineLayout layout = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreatePipelineLayout(device, &pli, nullptr, &layout));
  return UniquePipelineLayout(device, layout);
}

}  // namespace texstream::render::pass_objects
