#include "texstream/render/scene_passes.hpp"

#include <algorithm>
#include <array>
#include <cstddef>
#include <vector>

#include "texstream/common/scene_format.hpp"
#include "texstream/render/scene_gpu.hpp"
#include "texstream/render/shader_compiler.hpp"
#include "texstream/render/texture_cache.hpp"
#include "texstream/render/vk_check.hpp"
#include "texstream/render/vulkan_context.hpp"

namespace texstream::render {

namespace {

constexpr VkFormat kColourFormat = VK_FORMAT_R8G8B8A8_SRGB;
// Debug views write raw bytes (grey levels, heat colours, hashed ids) that a PNG must carry unchanged.
constexpr VkFormat kDebugColourFormat = VK_FORMAT_R8G8B8A8_UNORM;
// Reversed-Z wants float depth: precision is then nearly uniform in log-distance over near..far = 1..20000 m.
constexpr VkFormat kDepthFormat = VK_FORMAT_D32_SFLOAT;
constexpr VkShaderStageFlags kAllStages =
    VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT | VK_SHADER_STAGE_COMPUTE_BIT;

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

Result<UniqueRenderPass> make_render_pass(VkDevice device, bool with_colour, VkFormat colour_format) {
  std::vector<VkAttachmentDescription> atts;
  if (with_colour) {
    VkAttachmentDescription c{};
    c.format = colour_format;
    c.samples = VK_SAMPLE_COUNT_1_BIT;
    c.loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
    c.storeOp = VK_ATTACHMENT_STORE_OP_STORE;
    c.stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
    c.stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
    c.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
    c.finalLayout = VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL;  // frame capture copies it out
    atts.push_back(c);
  }
  VkAttachmentDescription d{};
  d.format = kDepthFormat;
  d.samples = VK_SAMPLE_COUNT_1_BIT;
  d.loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
  d.storeOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  d.stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
  d.stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  d.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  d.finalLayout = VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL;
  atts.push_back(d);

  VkAttachmentReference colour_ref{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
  VkAttachmentReference depth_ref{with_colour ? 1u : 0u, VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL};
  VkSubpassDescription sub{};
  sub.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
  sub.colorAttachmentCount = with_colour ? 1 : 0;
  sub.pColorAttachments = with_colour ? &colour_ref : nullptr;
  sub.pDepthStencilAttachment = &depth_ref;

  // In: the previous frame's use of the same attachments (and its capture copy) must be done before we clear.
  // Out: the capture copy reads the colour after the pass.
  std::array<VkSubpassDependency, 2> deps{};
  deps[0].srcSubpass = VK_SUBPASS_EXTERNAL;
  deps[0].dstSubpass = 0;
  deps[0].srcStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT |
                         VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[0].dstStageMask = VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT | VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[0].srcAccessMask = VK_ACCESS_TRANSFER_READ_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT |
                          VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[0].dstAccessMask = VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT |
                          VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[1].srcSubpass = 0;
  deps[1].dstSubpass = VK_SUBPASS_EXTERNAL;
  deps[1].srcStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[1].dstStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
  deps[1].srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[1].dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT;

  VkRenderPassCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO;
  ci.attachmentCount = static_cast<uint32_t>(atts.size());
  ci.pAttachments = atts.data();
  ci.subpassCount = 1;
  ci.pSubpasses = &sub;
  ci.dependencyCount = with_colour ? 2 : 1;
  ci.pDependencies = deps.data();
  VkRenderPass rp = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateRenderPass(device, &ci, nullptr, &rp));
  return UniqueRenderPass(device, rp);
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

}  // namespace

Result<uint32_t> debug_view_from_string(const std::string& name) {
  if (name == "none") return gpu::kDebugViewNone;
  if (name == "mip") return gpu::kDebugViewMip;
  if (name == "weight") return gpu::kDebugViewWeight;
  if (name == "mesh_id") return gpu::kDebugViewMeshId;
  return make_error(ErrorCode::kInvalidArgument,
                    "render.debug_view: '" + name + "' is not none, mip, weight or mesh_id");
}

VkFormat ScenePasses::colour_format() const {
  return options_.debug_view == gpu::kDebugViewNone ? kColourFormat : kDebugColourFormat;
}

Result<std::unique_ptr<ScenePasses>> ScenePasses::create(const VulkanContext& ctx, ShaderCompiler& compiler,
                                                         const ScenePassesOptions& options, const SceneGpu& scene,
                                                         const TextureCache& cache) {
  std::unique_ptr<ScenePasses> p(new ScenePasses(options, scene));
  TS_TRY(p->create_targets(ctx));
  TS_TRY(p->create_descriptors(ctx, cache));
  TS_TRY(p->create_pipelines(ctx, compiler));
  return p;
}

Status ScenePasses::create_targets(const VulkanContext& ctx) {
  VkDevice device = ctx.device();
  GpuImageInfo ci;
  ci.format = colour_format();
  ci.width = options_.width;
  ci.height = options_.height;
  ci.usage = VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT;
  auto colour = GpuImage::create(ctx, ci);
  if (!colour) return colour.error();
  colour_ = std::move(*colour);
  GpuImageInfo di = ci;
  di.format = kDepthFormat;
  di.usage = VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT;
  di.aspect = VK_IMAGE_ASPECT_DEPTH_BIT;
  auto depth = GpuImage::create(ctx, di);
  if (!depth) return depth.error();
  depth_ = std::move(*depth);
  di.width = options_.wide_width;
  di.height = options_.wide_height;
  auto wide = GpuImage::create(ctx, di);
  if (!wide) return wide.error();
  wide_depth_ = std::move(*wide);

  auto main_pass = make_render_pass(device, true, colour_format());
  if (!main_pass) return main_pass.error();
  main_pass_ = std::move(*main_pass);
  auto wide_pass = make_render_pass(device, false, colour_format());
  if (!wide_pass) return wide_pass.error();
  wide_pass_ = std::move(*wide_pass);
  auto main_fb = make_framebuffer(device, main_pass_.get(), {colour_.view(), depth_.view()}, options_.width,
                                  options_.height);
  if (!main_fb) return main_fb.error();
  main_fb_ = std::move(*main_fb);
  auto wide_fb = make_framebuffer(device, wide_pass_.get(), {wide_depth_.view()}, options_.wide_width,
                                  options_.wide_height);
  if (!wide_fb) return wide_fb.error();
  wide_fb_ = std::move(*wide_fb);

  // The probe buffer: one sample per viewport pixel when probing, else one entry to keep the binding valid.
  const VkDeviceSize probe_bytes =
      sizeof(gpu::LodProbeSample) *
      (options_.lod_probe ? static_cast<VkDeviceSize>(options_.width) * options_.height : 1);
  auto probe = GpuBuffer::create(ctx, probe_bytes, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, MemoryUse::kHostVisible);
  if (!probe) return probe.error();
  probe_ = std::move(*probe);
  std::fill_n(probe_.bytes().data(), probe_bytes, std::byte{0});
  return ok_status();
}

Status ScenePasses::create_descriptors(const VulkanContext& ctx, const TextureCache& cache) {
  VkDevice device = ctx.device();
  VkSamplerCreateInfo si{};
  si.sType = VK_STRUCTURE_TYPE_SAMPLER_CREATE_INFO;
  si.magFilter = VK_FILTER_LINEAR;
  si.minFilter = VK_FILTER_LINEAR;
  si.mipmapMode = VK_SAMPLER_MIPMAP_MODE_LINEAR;
  si.addressModeU = si.addressModeV = si.addressModeW = VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
  // No sampler anisotropy: scene.frag takes A_s taps itself so that no tap can reach a non-resident level.
  si.anisotropyEnable = VK_FALSE;
  si.minLod = 0.0f;
  si.maxLod = VK_LOD_CLAMP_NONE;
  VkSampler sampler = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateSampler(device, &si, nullptr, &sampler));
  sampler_ = UniqueSampler(device, sampler);
  // The probe sampler asks the device which level it would pick under anisotropy A_m (textureQueryLod).
  probe_anisotropic_ = ctx.sampler_anisotropy();
  si.anisotropyEnable = probe_anisotropic_ ? VK_TRUE : VK_FALSE;
  si.maxAnisotropy = std::min(options_.probe_anisotropy, ctx.properties().limits.maxSamplerAnisotropy);
  if (!probe_anisotropic_) si.maxAnisotropy = 1.0f;
  VkSampler probe_sampler = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateSampler(device, &si, nullptr, &probe_sampler));
  probe_sampler_ = UniqueSampler(device, probe_sampler);

  const std::array<VkDescriptorSetLayoutBinding, 9> bindings{{
      {gpu::kBindingFrame, VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingMeshes, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingTextures, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingMeshMeta, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingCache, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 1, VK_SHADER_STAGE_FRAGMENT_BIT, nullptr},
      {gpu::kBindingCompacted, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingReadback, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingLodProbe, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingProbeSampler, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 1, VK_SHADER_STAGE_FRAGMENT_BIT, nullptr},
  }};
  VkDescriptorSetLayoutCreateInfo li{};
  li.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO;
  li.bindingCount = static_cast<uint32_t>(bindings.size());
  li.pBindings = bindings.data();
  VkDescriptorSetLayout set_layout = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateDescriptorSetLayout(device, &li, nullptr, &set_layout));
  set_layout_ = UniqueDescriptorSetLayout(device, set_layout);

  const std::array<VkDescriptorPoolSize, 3> sizes{{{VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, 1},
                                                   {VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 6},
                                                   {VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 2}}};
  VkDescriptorPoolCreateInfo pi{};
  pi.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO;
  pi.maxSets = 1;
  pi.poolSizeCount = static_cast<uint32_t>(sizes.size());
  pi.pPoolSizes = sizes.data();
  VkDescriptorPool pool = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateDescriptorPool(device, &pi, nullptr, &pool));
  pool_ = UniqueDescriptorPool(device, pool);
  VkDescriptorSetAllocateInfo ai{};
  ai.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO;
  ai.descriptorPool = pool;
  ai.descriptorSetCount = 1;
  ai.pSetLayouts = &set_layout;
  TS_VK_TRY(vkAllocateDescriptorSets(device, &ai, &set_));

  constexpr size_t kBuffers = 7;
  const std::array<VkDescriptorBufferInfo, kBuffers> buffers{{
      {scene_.frame_uniforms.handle(), 0, VK_WHOLE_SIZE},
      {scene_.meshes.handle(), 0, VK_WHOLE_SIZE},
      {cache.texture_table(), 0, VK_WHOLE_SIZE},
      {scene_.mesh_meta.handle(), 0, VK_WHOLE_SIZE},
      {scene_.compacted.handle(), 0, VK_WHOLE_SIZE},
      {scene_.readback.handle(), 0, VK_WHOLE_SIZE},
      {probe_.handle(), 0, VK_WHOLE_SIZE},
  }};
  const VkDescriptorImageInfo image{sampler_.get(), cache.image_view(), VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL};
  const VkDescriptorImageInfo probe_image{probe_sampler_.get(), cache.image_view(),
                                          VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL};
  std::array<VkWriteDescriptorSet, kBuffers + 2> writes{};
  const std::array<uint32_t, kBuffers> buffer_bindings{gpu::kBindingFrame,     gpu::kBindingMeshes,
                                                       gpu::kBindingTextures,  gpu::kBindingMeshMeta,
                                                       gpu::kBindingCompacted, gpu::kBindingReadback,
                                                       gpu::kBindingLodProbe};
  for (size_t i = 0; i < kBuffers; ++i) {
    writes[i] = {};
    writes[i].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
    writes[i].dstSet = set_;
    writes[i].dstBinding = buffer_bindings[i];
    writes[i].descriptorCount = 1;
    writes[i].descriptorType = i == 0 ? VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    writes[i].pBufferInfo = &buffers[i];
  }
  for (size_t k = 0; k < 2; ++k) {
    VkWriteDescriptorSet& w = writes[kBuffers + k];
    w = {};
    w.sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
    w.dstSet = set_;
    w.dstBinding = k == 0 ? gpu::kBindingCache : gpu::kBindingProbeSampler;
    w.descriptorCount = 1;
    w.descriptorType = VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER;
    w.pImageInfo = k == 0 ? &image : &probe_image;
  }
  vkUpdateDescriptorSets(device, static_cast<uint32_t>(writes.size()), writes.data(), 0, nullptr);

  VkPushConstantRange range{kAllStages, 0, sizeof(gpu::PassConstants)};
  VkPipelineLayoutCreateInfo pli{};
  pli.sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO;
  pli.setLayoutCount = 1;
  pli.pSetLayouts = &set_layout;
  pli.pushConstantRangeCount = 1;
  pli.pPushConstantRanges = &range;
  VkPipelineLayout layout = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreatePipelineLayout(device, &pli, nullptr, &layout));
  layout_ = UniquePipelineLayout(device, layout);
  return ok_status();
}

Status ScenePasses::create_pipelines(const VulkanContext& ctx, ShaderCompiler& compiler) {
  VkDevice device = ctx.device();
  auto vert = make_module(ctx, compiler, {"scene.vert", ShaderStage::kVertex, {}});
  if (!vert) return vert.error();
  std::vector<std::string> main_defines;
  if (options_.lod_probe) main_defines.push_back("LOD_PROBE");
  auto frag = make_module(ctx, compiler, {"scene.frag", ShaderStage::kFragment, main_defines});
  if (!frag) return frag.error();
  auto wide_frag = make_module(ctx, compiler, {"scene.frag", ShaderStage::kFragment, {"WIDE_PASS"}});
  if (!wide_frag) return wide_frag.error();
  auto comp = make_module(ctx, compiler, {"compact.comp", ShaderStage::kCompute, {}});
  if (!comp) return comp.error();
  auto args = make_module(ctx, compiler, {"compact_args.comp", ShaderStage::kCompute, {}});
  if (!args) return args.error();
  auto copy = make_module(ctx, compiler, {"compact_copy.comp", ShaderStage::kCompute, {}});
  if (!copy) return copy.error();

  VkVertexInputBindingDescription vb{0, sizeof(scene::Vertex), VK_VERTEX_INPUT_RATE_VERTEX};
  const std::array<VkVertexInputAttributeDescription, 3> va{{
      {0, 0, VK_FORMAT_R32G32B32_SFLOAT, offsetof(scene::Vertex, pos)},
      {1, 0, VK_FORMAT_R32G32B32_SFLOAT, offsetof(scene::Vertex, normal)},
      {2, 0, VK_FORMAT_R32G32_SFLOAT, offsetof(scene::Vertex, uv)},
  }};
  VkPipelineVertexInputStateCreateInfo vi{};
  vi.sType = VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO;
  vi.vertexBindingDescriptionCount = 1;
  vi.pVertexBindingDescriptions = &vb;
  vi.vertexAttributeDescriptionCount = static_cast<uint32_t>(va.size());
  vi.pVertexAttributeDescriptions = va.data();
  VkPipelineInputAssemblyStateCreateInfo ia{};
  ia.sType = VK_STRUCTURE_TYPE_PIPELINE_INPUT_ASSEMBLY_STATE_CREATE_INFO;
  ia.topology = VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST;
  VkPipelineViewportStateCreateInfo vp{};
  vp.sType = VK_STRUCTURE_TYPE_PIPELINE_VIEWPORT_STATE_CREATE_INFO;
  vp.viewportCount = 1;
  vp.scissorCount = 1;
  VkPipelineRasterizationStateCreateInfo rs{};
  rs.sType = VK_STRUCTURE_TYPE_PIPELINE_RASTERIZATION_STATE_CREATE_INFO;
  rs.polygonMode = VK_POLYGON_MODE_FILL;
  rs.cullMode = VK_CULL_MODE_NONE;  // city meshes are not consistently wound
  rs.frontFace = VK_FRONT_FACE_COUNTER_CLOCKWISE;
  rs.lineWidth = 1.0f;
  VkPipelineMultisampleStateCreateInfo ms{};
  ms.sType = VK_STRUCTURE_TYPE_PIPELINE_MULTISAMPLE_STATE_CREATE_INFO;
  ms.rasterizationSamples = VK_SAMPLE_COUNT_1_BIT;
  VkPipelineDepthStencilStateCreateInfo ds{};
  ds.sType = VK_STRUCTURE_TYPE_PIPELINE_DEPTH_STENCIL_STATE_CREATE_INFO;
  ds.depthTestEnable = VK_TRUE;
  VkPipelineColorBlendAttachmentState cba{};
  cba.colorWriteMask =
      VK_COLOR_COMPONENT_R_BIT | VK_COLOR_COMPONENT_G_BIT | VK_COLOR_COMPONENT_B_BIT | VK_COLOR_COMPONENT_A_BIT;
  VkPipelineColorBlendStateCreateInfo cb{};
  cb.sType = VK_STRUCTURE_TYPE_PIPELINE_COLOR_BLEND_STATE_CREATE_INFO;
  const std::array<VkDynamicState, 2> dyn{VK_DYNAMIC_STATE_VIEWPORT, VK_DYNAMIC_STATE_SCISSOR};
  VkPipelineDynamicStateCreateInfo dy{};
  dy.sType = VK_STRUCTURE_TYPE_PIPELINE_DYNAMIC_STATE_CREATE_INFO;
  dy.dynamicStateCount = static_cast<uint32_t>(dyn.size());
  dy.pDynamicStates = dyn.data();

  // fs = VK_NULL_HANDLE: the depth-only pre-pass (no fragment stage, colour writes masked).
  auto graphics = [&](VkShaderModule fs, VkRenderPass pass, bool colour, VkCompareOp compare, bool depth_write,
                      UniquePipeline& out) -> Status {
    ds.depthCompareOp = compare;
    ds.depthWriteEnable = depth_write ? VK_TRUE : VK_FALSE;
    cba.colorWriteMask = fs == VK_NULL_HANDLE ? 0u
                                              : VK_COLOR_COMPONENT_R_BIT | VK_COLOR_COMPONENT_G_BIT |
                                                    VK_COLOR_COMPONENT_B_BIT | VK_COLOR_COMPONENT_A_BIT;
    std::array<VkPipelineShaderStageCreateInfo, 2> stages{};
    stages[0] = {};
    stages[0].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    stages[0].stage = VK_SHADER_STAGE_VERTEX_BIT;
    stages[0].module = vert->get();
    stages[0].pName = "main";
    stages[1] = {};
    stages[1].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    stages[1].stage = VK_SHADER_STAGE_FRAGMENT_BIT;
    stages[1].module = fs;
    stages[1].pName = "main";
    cb.attachmentCount = colour ? 1 : 0;
    cb.pAttachments = colour ? &cba : nullptr;
    VkGraphicsPipelineCreateInfo gi{};
    gi.sType = VK_STRUCTURE_TYPE_GRAPHICS_PIPELINE_CREATE_INFO;
    gi.stageCount = fs == VK_NULL_HANDLE ? 1u : 2u;
    gi.pStages = stages.data();
    gi.pVertexInputState = &vi;
    gi.pInputAssemblyState = &ia;
    gi.pViewportState = &vp;
    gi.pRasterizationState = &rs;
    gi.pMultisampleState = &ms;
    gi.pDepthStencilState = &ds;
    gi.pColorBlendState = &cb;
    gi.pDynamicState = &dy;
    gi.layout = layout_.get();
    gi.renderPass = pass;
    gi.subpass = 0;
    VkPipeline p = VK_NULL_HANDLE;
    TS_VK_TRY(vkCreateGraphicsPipelines(device, VK_NULL_HANDLE, 1, &gi, nullptr, &p));
    out = UniquePipeline(device, p);
    return ok_status();
  };
  // Reversed Z: nearer is larger. The pre-pass resolves visibility; the shading draw keeps only the fragments
  // whose depth equals the winner's (bit-identical through `invariant gl_Position`).
  TS_TRY(graphics(VK_NULL_HANDLE, main_pass_.get(), true, VK_COMPARE_OP_GREATER, true, prepass_pipeline_));
  TS_TRY(graphics(frag->get(), main_pass_.get(), true, VK_COMPARE_OP_EQUAL, false, main_pipeline_));
  TS_TRY(graphics(wide_frag->get(), wide_pass_.get(), false, VK_COMPARE_OP_GREATER, true, wide_pipeline_));

  auto compute = [&](VkShaderModule module, UniquePipeline& out) -> Status {
    VkComputePipelineCreateInfo ci{};
    ci.sType = VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO;
    ci.stage = {};
    ci.stage.sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    ci.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
    ci.stage.module = module;
    ci.stage.pName = "main";
    ci.layout = layout_.get();
    VkPipeline p = VK_NULL_HANDLE;
    TS_VK_TRY(vkCreateComputePipelines(device, VK_NULL_HANDLE, 1, &ci, nullptr, &p));
    out = UniquePipeline(device, p);
    return ok_status();
  };
  TS_TRY(compute(comp->get(), compact_pipeline_));
  TS_TRY(compute(args->get(), compact_args_pipeline_));
  TS_TRY(compute(copy->get(), compact_copy_pipeline_));
  return ok_status();
}

void ScenePasses::record(VkCommandBuffer cmd, const FrameRecording& frame) const {
  // The fields of the frame uniforms that describe these passes (the caller fills the rest before record()).
  auto* fu = scene_.frame_uniforms.as<gpu::FrameUniforms>();
  fu->flags.x = frame.feedback ? (fu->flags.x | gpu::kFlagFeedback) : (fu->flags.x & ~gpu::kFlagFeedback);
  fu->view = {options_.debug_view, options_.width, 0, 0};

  // The previous submission's compaction wrote the sparse metadata and the list counter; this frame's fragment
  // atomics and the counter reset come after it (submission order + this barrier).
  memory_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_SHADER_READ_BIT,
                 VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                 VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT);
  if (frame.feedback) vkCmdFillBuffer(cmd, scene_.compacted.handle(), 0, sizeof(gpu::CompactListHeader), 0);

  const VkDeviceSize zero = 0;
  auto draw_pass = [&](VkRenderPass pass, VkFramebuffer fb, uint32_t w, uint32_t h, VkPipeline prepass,
                       VkPipeline pipeline, const gpu::PassConstants& pc, bool colour) {
    std::array<VkClearValue, 2> clears{};
    // Sky colour in linear light (the attachment is sRGB); the id view clears to 0 = "no mesh". Depth 0 is
    // "infinitely far" with reversed Z.
    clears[0].color = {{0.45f, 0.6f, 0.8f, 1.0f}};
    if (options_.debug_view == gpu::kDebugViewMeshId) clears[0].color = {{0.0f, 0.0f, 0.0f, 1.0f}};
    clears[colour ? 1 : 0].depthStencil = {0.0f, 0};
    VkRenderPassBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO;
    bi.renderPass = pass;
    bi.framebuffer = fb;
    bi.renderArea = {{0, 0}, {w, h}};
    bi.clearValueCount = colour ? 2 : 1;
    bi.pClearValues = clears.data();
    vkCmdBeginRenderPass(cmd, &bi, VK_SUBPASS_CONTENTS_INLINE);
    const VkViewport viewport{0, 0, static_cast<float>(w), static_cast<float>(h), 0, 1};
    const VkRect2D scissor{{0, 0}, {w, h}};
    vkCmdSetViewport(cmd, 0, 1, &viewport);
    vkCmdSetScissor(cmd, 0, 1, &scissor);
    if (frame.draw_count > 0) {
      vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, layout_.get(), 0, 1, &set_, 0, nullptr);
      vkCmdPushConstants(cmd, layout_.get(), kAllStages, 0, sizeof pc, &pc);
      VkBuffer vb = scene_.vertices.handle();
      vkCmdBindVertexBuffers(cmd, 0, 1, &vb, &zero);
      vkCmdBindIndexBuffer(cmd, scene_.indices.handle(), 0, VK_INDEX_TYPE_UINT32);
      // Every surviving mesh in one multi-draw indirect call per pipeline (seed 001: few calls).
      for (VkPipeline p : {prepass, pipeline}) {
        if (p == VK_NULL_HANDLE) continue;
        vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, p);
        vkCmdDrawIndexedIndirect(cmd, scene_.indirect.handle(), 0, frame.draw_count,
                                 sizeof(VkDrawIndexedIndirectCommand));
      }
    }
    vkCmdEndRenderPass(cmd);
  };
  draw_pass(main_pass_.get(), main_fb_.get(), options_.width, options_.height, prepass_pipeline_.get(),
            main_pipeline_.get(), frame.main, true);
  if (!frame.feedback) return;
  draw_pass(wide_pass_.get(), wide_fb_.get(), options_.wide_width, options_.wide_height, VK_NULL_HANDLE,
            wide_pipeline_.get(), frame.wide, false);

  // Compaction reads what both passes' fragment shaders wrote and the cleared counter.
  memory_barrier(cmd, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                 VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                 VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
  vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, layout_.get(), 0, 1, &set_, 0, nullptr);
  vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, compact_pipeline_.get());
  const uint32_t groups = (scene_.mesh_count + gpu::kCompactWorkgroupSize - 1) / gpu::kCompactWorkgroupSize;
  if (groups > 0) vkCmdDispatch(cmd, groups, 1, 1);

  if (frame.read_back_list) {
    // The final count -> the copy's group count (written into the list header), then the used prefix only.
    memory_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                   VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, compact_args_pipeline_.get());
    vkCmdDispatch(cmd, 1, 1, 1);
    memory_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                   VK_PIPELINE_STAGE_DRAW_INDIRECT_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                   VK_ACCESS_INDIRECT_COMMAND_READ_BIT | VK_ACCESS_SHADER_READ_BIT);
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, compact_copy_pipeline_.get());
    vkCmdDispatchIndirect(cmd, scene_.compacted.handle(), offsetof(gpu::CompactListHeader, dispatch));
    memory_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT, VK_PIPELINE_STAGE_HOST_BIT,
                   VK_ACCESS_HOST_READ_BIT);
  }
}

}  // namespace texstream::render
