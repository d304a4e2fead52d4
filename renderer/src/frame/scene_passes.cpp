#include "texstream/render/frame/scene_passes.hpp"

#include <algorithm>
#include <array>
#include <cstddef>
#include <span>
#include <utility>
#include <vector>

#include "scene_pass_objects.hpp"
#include "texstream/common/contract.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/render/cache/ground_pages.hpp"
#include "texstream/render/cache/texture_cache.hpp"
#include "texstream/render/scene/scene_gpu.hpp"
#include "texstream/render/vulkan/shader_compiler.hpp"
#include "texstream/render/vulkan/vk_check.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

namespace texstream::render {

// The passes are made of these objects (scene_pass_objects.hpp).
using namespace pass_objects;

uint32_t gpu_debug_view(DebugView view) {
  switch (view) {
    case DebugView::kNone:
      return gpu::kDebugViewNone;
    case DebugView::kMip:
      return gpu::kDebugViewMip;
    case DebugView::kWeight:
      return gpu::kDebugViewWeight;
    case DebugView::kMeshId:
      return gpu::kDebugViewMeshId;
    case DebugView::kPageLevel:
      return gpu::kDebugViewPageLevel;
    case DebugView::kPageResidency:
      return gpu::kDebugViewPageResidency;
  }
  TS_UNREACHABLE("render.debug_view %d is outside its table", static_cast<int>(view));
}

VkFormat ScenePasses::colour_format() const {
  return options_.debug_view == gpu::kDebugViewNone ? kColourFormat : kDebugColourFormat;
}

Result<std::unique_ptr<ScenePasses>> ScenePasses::create(const VulkanContext& ctx, ShaderCompiler& compiler,
                                                         const ScenePassesOptions& options, const SceneGpu& scene,
                                                         const TextureCache& cache, const GroundPages* ground) {
  std::unique_ptr<ScenePasses> p(new ScenePasses(options, scene));
  p->ground_ = ground;
  p->device_ = ctx.device();
  if (options.timestamps) {
    if (ctx.properties().limits.timestampComputeAndGraphics != VK_TRUE) {
      return make_error(ErrorCode::kUnsupported, "device '" + ctx.device_name() + "' has no timestamps on its queue");
    }
    p->timestamp_period_ns_ = static_cast<double>(ctx.properties().limits.timestampPeriod);
    VkQueryPoolCreateInfo qi{};
    qi.sType = VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO;
    qi.queryType = VK_QUERY_TYPE_TIMESTAMP;
    qi.queryCount = kTimestampCount;
    VkQueryPool pool = VK_NULL_HANDLE;
    TS_VK_TRY(vkCreateQueryPool(ctx.device(), &qi, nullptr, &pool));
    p->timestamps_ = UniqueQueryPool(ctx.device(), pool);
  }
  TS_TRY(p->create_targets(ctx));
  TS_TRY(p->create_descriptors(ctx, cache));
  if (ground) TS_TRY(p->create_ground_descriptors(ctx));
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
  GpuImageInfo oi = ci;
  oi.format = kOwnerFormat;
  oi.usage = VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_INPUT_ATTACHMENT_BIT;
  auto owner = GpuImage::create(ctx, oi);
  if (!owner) return owner.error();
  owner_ = std::move(*owner);
  GpuImageInfo mi = ci;
  mi.format = kMetaFormat;
  mi.usage = VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_STORAGE_BIT;
  auto meta = GpuImage::create(ctx, mi);
  if (!meta) return meta.error();
  meta_ = std::move(*meta);
  di.width = options_.wide_width;
  di.height = options_.wide_height;
  auto wide = GpuImage::create(ctx, di);
  if (!wide) return wide.error();
  wide_depth_ = std::move(*wide);

  auto main_pass = make_main_pass(device, colour_format());
  if (!main_pass) return main_pass.error();
  main_pass_ = std::move(*main_pass);
  auto wide_pass = make_wide_pass(device);
  if (!wide_pass) return wide_pass.error();
  wide_pass_ = std::move(*wide_pass);
  auto main_fb =
      make_framebuffer(device, main_pass_.get(), {colour_.view(), depth_.view(), owner_.view(), meta_.view()},
                       options_.width, options_.height);
  if (!main_fb) return main_fb.error();
  main_fb_ = std::move(*main_fb);
  auto wide_fb =
      make_framebuffer(device, wide_pass_.get(), {wide_depth_.view()}, options_.wide_width, options_.wide_height);
  if (!wide_fb) return wide_fb.error();
  wide_fb_ = std::move(*wide_fb);

  // The probe buffer: one sample per viewport pixel when probing, else one entry to keep the binding valid.
  const VkDeviceSize probe_bytes =
      sizeof(gpu::LodProbeSample) *
      (options_.lod_probe ? static_cast<VkDeviceSize>(options_.width) * options_.height : 1);
  auto probe = GpuBuffer::create(ctx, probe_bytes, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, MemoryUse::kHostRead);
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

  const std::array<VkDescriptorSetLayoutBinding, 13> bindings{{
      {gpu::kBindingFrame, VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingMeshes, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingTextures, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingMeshMeta, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingCache, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, gpu::kCachePlanes, VK_SHADER_STAGE_FRAGMENT_BIT,
       nullptr},
      {gpu::kBindingCompacted, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingReadback, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingLodProbe, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, kAllStages, nullptr},
      {gpu::kBindingProbeSampler, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 1, VK_SHADER_STAGE_FRAGMENT_BIT, nullptr},
      {gpu::kBindingOwner, VK_DESCRIPTOR_TYPE_INPUT_ATTACHMENT, 1, VK_SHADER_STAGE_FRAGMENT_BIT, nullptr},
      {gpu::kBindingDrawn, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, VK_SHADER_STAGE_COMPUTE_BIT, nullptr},
      {gpu::kBindingMetaImage, VK_DESCRIPTOR_TYPE_STORAGE_IMAGE, 1, VK_SHADER_STAGE_COMPUTE_BIT, nullptr},
      {gpu::kBindingInstances, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, VK_SHADER_STAGE_VERTEX_BIT, nullptr},
  }};
  auto single = make_single_set(device, bindings);
  if (!single) return single.error();
  SingleSet main_set = std::move(*single);
  set_layout_ = std::move(main_set.layout);
  pool_ = std::move(main_set.pool);
  set_ = main_set.set;
  VkDescriptorSetLayout set_layout = set_layout_.get();

  constexpr size_t kBuffers = 9;
  const std::array<VkDescriptorBufferInfo, kBuffers> buffers{{
      {scene_.frame_uniforms().handle(), 0, VK_WHOLE_SIZE},
      {scene_.meshes().handle(), 0, VK_WHOLE_SIZE},
      {cache.texture_table(), 0, VK_WHOLE_SIZE},
      {scene_.mesh_meta().handle(), 0, VK_WHOLE_SIZE},
      {scene_.compacted().handle(), 0, VK_WHOLE_SIZE},
      {scene_.readback().handle(), 0, VK_WHOLE_SIZE},
      {probe_.handle(), 0, VK_WHOLE_SIZE},
      {scene_.drawn().handle(), 0, VK_WHOLE_SIZE},
      {scene_.instances().handle(), 0, VK_WHOLE_SIZE},
  }};
  // One descriptor per plane; the planes the scene lacks repeat plane 0 (never sampled: no texture names them).
  std::array<VkDescriptorImageInfo, gpu::kCachePlanes> planes{};
  for (uint32_t i = 0; i < gpu::kCachePlanes; ++i) {
    planes[i] = {sampler_.get(), cache.image_view(i < cache.plane_count() ? i : 0),
                 VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL};
  }
  const VkDescriptorImageInfo probe_image{probe_sampler_.get(), cache.image_view(),
                                          VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL};
  const VkDescriptorImageInfo owner_image{VK_NULL_HANDLE, owner_.view(), VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL};
  // A storage image, not a sampled one: meta_reduce.comp's imageLoad costs lavapipe ~20 % less than
  // texelFetch through a sampler (its compute time over 60 renderer frames, perf samples).
  const VkDescriptorImageInfo meta_texels{VK_NULL_HANDLE, meta_.view(), VK_IMAGE_LAYOUT_GENERAL};
  std::array<VkWriteDescriptorSet, kBuffers + 4> writes{};
  const std::array<uint32_t, kBuffers> buffer_bindings{
      gpu::kBindingFrame,    gpu::kBindingMeshes,    gpu::kBindingTextures,
      gpu::kBindingMeshMeta, gpu::kBindingCompacted, gpu::kBindingReadback,
      gpu::kBindingLodProbe, gpu::kBindingDrawn,     gpu::kBindingInstances};
  for (size_t i = 0; i < kBuffers; ++i) {
    writes[i] = {};
    writes[i].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
    writes[i].dstSet = set_;
    writes[i].dstBinding = buffer_bindings[i];
    writes[i].descriptorCount = 1;
    writes[i].descriptorType = i == 0 ? VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    writes[i].pBufferInfo = &buffers[i];
  }
  const std::array<std::pair<uint32_t, const VkDescriptorImageInfo*>, 3> sampled{{
      {gpu::kBindingCache, planes.data()},
      {gpu::kBindingProbeSampler, &probe_image},
      {gpu::kBindingMetaImage, &meta_texels},
  }};  // the last one a storage image
  for (size_t k = 0; k < sampled.size(); ++k) {
    VkWriteDescriptorSet& w = writes[kBuffers + 1 + k];
    w = {};
    w.sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
    w.dstSet = set_;
    w.dstBinding = sampled[k].first;
    w.descriptorCount = sampled[k].first == gpu::kBindingCache ? gpu::kCachePlanes : 1;
    w.descriptorType = sampled[k].first == gpu::kBindingMetaImage ? VK_DESCRIPTOR_TYPE_STORAGE_IMAGE
                                                                  : VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER;
    w.pImageInfo = sampled[k].second;
  }
  VkWriteDescriptorSet& ow = writes[kBuffers];
  ow = {};
  ow.sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
  ow.dstSet = set_;
  ow.dstBinding = gpu::kBindingOwner;
  ow.descriptorCount = 1;
  ow.descriptorType = VK_DESCRIPTOR_TYPE_INPUT_ATTACHMENT;
  ow.pImageInfo = &owner_image;
  vkUpdateDescriptorSets(device, static_cast<uint32_t>(writes.size()), writes.data(), 0, nullptr);
  texture_table_ = cache.texture_table();

  auto layout = make_pipeline_layout(device, std::span<const VkDescriptorSetLayout>(&set_layout, 1));
  if (!layout) return layout.error();
  layout_ = std::move(*layout);
  return ok_status();
}

Status ScenePasses::create_ground_descriptors(const VulkanContext& ctx) {
  VkDevice device = ctx.device();
  VkSamplerCreateInfo si{};
  si.sType = VK_STRUCTURE_TYPE_SAMPLER_CREATE_INFO;
  // Bilinear inside one bordered page (a frame has one level; ground.frag blends two levels itself).
  si.magFilter = si.minFilter = VK_FILTER_LINEAR;
  // The reference (pages.reference) is one mipmapped image: trilinear by the sampler.
  si.mipmapMode = ground_->reference() ? VK_SAMPLER_MIPMAP_MODE_LINEAR : VK_SAMPLER_MIPMAP_MODE_NEAREST;
  si.addressModeU = si.addressModeV = si.addressModeW = VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
  si.maxLod = ground_->reference() ? VK_LOD_CLAMP_NONE : 0.0f;
  VkSampler sampler = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateSampler(device, &si, nullptr, &sampler));
  ground_sampler_ = UniqueSampler(device, sampler);
  const std::array<VkDescriptorSetLayoutBinding, 4> bindings{{
      {gpu::kGroundBindingUniforms, VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, 1,
       VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT, nullptr},
      {gpu::kGroundBindingFrames, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 1, VK_SHADER_STAGE_FRAGMENT_BIT, nullptr},
      {gpu::kGroundBindingTable, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, VK_SHADER_STAGE_FRAGMENT_BIT, nullptr},
      {gpu::kGroundBindingNeeds, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, VK_SHADER_STAGE_FRAGMENT_BIT, nullptr},
  }};
  auto single = make_single_set(device, bindings);
  if (!single) return single.error();
  SingleSet ground_set = std::move(*single);
  ground_set_layout_ = std::move(ground_set.layout);
  ground_pool_ = std::move(ground_set.pool);
  ground_set_ = ground_set.set;
  const VkDescriptorBufferInfo uniforms{ground_->uniforms(), 0, VK_WHOLE_SIZE};
  const VkDescriptorBufferInfo table{ground_->table(), 0, VK_WHOLE_SIZE};
  const VkDescriptorBufferInfo needs{ground_->needs(), 0, VK_WHOLE_SIZE};
  const VkDescriptorImageInfo frames{ground_sampler_.get(), ground_->frames_view(),
                                     VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL};
  std::array<VkWriteDescriptorSet, 4> w{};
  for (auto& x : w) {
    x.sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
    x.dstSet = ground_set_;
    x.descriptorCount = 1;
  }
  w[0].dstBinding = gpu::kGroundBindingUniforms;
  w[0].descriptorType = VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER;
  w[0].pBufferInfo = &uniforms;
  w[1].dstBinding = gpu::kGroundBindingFrames;
  w[1].descriptorType = VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER;
  w[1].pImageInfo = &frames;
  w[2].dstBinding = gpu::kGroundBindingTable;
  w[2].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
  w[2].pBufferInfo = &table;
  w[3].dstBinding = gpu::kGroundBindingNeeds;
  w[3].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
  w[3].pBufferInfo = &needs;
  vkUpdateDescriptorSets(device, static_cast<uint32_t>(w.size()), w.data(), 0, nullptr);

  // Set 0 as every pipeline has it, set 1 the ground's: binding set 0 once serves both layouts.
  const std::array<VkDescriptorSetLayout, 2> layouts{set_layout_.get(), ground_set_layout_.get()};
  auto layout = make_pipeline_layout(device, layouts);
  if (!layout) return layout.error();
  ground_layout_ = std::move(*layout);
  return ok_status();
}

Status ScenePasses::create_pipelines(const VulkanContext& ctx, ShaderCompiler& compiler) {
  VkDevice device = ctx.device();
  auto vert = make_module(ctx, compiler, {"scene.vert", ShaderStage::kVertex, {}});
  if (!vert) return vert.error();
  std::vector<std::string> main_defines;
  std::vector<std::string> wide_defines{"WIDE_PASS"};
  if (options_.lod_probe) main_defines.push_back("LOD_PROBE");
  if (options_.subgroup_reduce && ctx.subgroup_reductions(VK_SHADER_STAGE_FRAGMENT_BIT))
    wide_defines.push_back("SUBGROUP_FEEDBACK");

  auto frag = make_module(ctx, compiler, {"scene.frag", ShaderStage::kFragment, main_defines});
  if (!frag) return frag.error();
  // Only a scene with alpha-tested textures gets the pre-pass that samples and discards: a shader that may
  // discard loses early depth writes, which every other scene keeps.
  std::vector<std::string> prepass_defines;
  if (options_.alpha_test) prepass_defines.push_back("ALPHA_TEST");
  auto prepass = make_module(ctx, compiler, {"prepass.frag", ShaderStage::kFragment, prepass_defines});
  if (!prepass) return prepass.error();
  auto wide_frag = make_module(ctx, compiler, {"scene.frag", ShaderStage::kFragment, wide_defines});
  if (!wide_frag) return wide_frag.error();
  auto reduce = make_module(ctx, compiler, {"meta_reduce.comp", ShaderStage::kCompute, {}});
  if (!reduce) return reduce.error();
  auto comp = make_module(ctx, compiler, {"compact.comp", ShaderStage::kCompute, {}});
  if (!comp) return comp.error();
  auto to_host = make_module(ctx, compiler, {"compact.comp", ShaderStage::kCompute, {"COMPACT_TO_HOST"}});
  if (!to_host) return to_host.error();

  // Binding 1: the owning mesh's id per vertex (SceneGpu::vertex_mesh), so one draw can cover many meshes.
  const std::array<VkVertexInputBindingDescription, 2> vb{{
      {0, sizeof(scene::Vertex), VK_VERTEX_INPUT_RATE_VERTEX},
      {1, sizeof(uint32_t), VK_VERTEX_INPUT_RATE_VERTEX},
  }};
  const std::array<VkVertexInputAttributeDescription, 4> va{{
      {0, 0, VK_FORMAT_R32G32B32_SFLOAT, offsetof(scene::Vertex, pos)},
      {1, 0, VK_FORMAT_R32G32B32_SFLOAT, offsetof(scene::Vertex, normal)},
      {2, 0, VK_FORMAT_R32G32_SFLOAT, offsetof(scene::Vertex, uv)},
      {gpu::kVertexMeshLocation, 1, VK_FORMAT_R32_UINT, 0},
  }};
  VkPipelineVertexInputStateCreateInfo vi{};
  vi.sType = VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO;
  vi.vertexBindingDescriptionCount = static_cast<uint32_t>(vb.size());
  vi.pVertexBindingDescriptions = vb.data();
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
  std::array<VkPipelineColorBlendAttachmentState, 2> cba{};
  VkPipelineColorBlendStateCreateInfo cb{};
  cb.sType = VK_STRUCTURE_TYPE_PIPELINE_COLOR_BLEND_STATE_CREATE_INFO;
  const std::array<VkDynamicState, 2> dyn{VK_DYNAMIC_STATE_VIEWPORT, VK_DYNAMIC_STATE_SCISSOR};
  VkPipelineDynamicStateCreateInfo dy{};
  dy.sType = VK_STRUCTURE_TYPE_PIPELINE_DYNAMIC_STATE_CREATE_INFO;
  dy.dynamicStateCount = static_cast<uint32_t>(dyn.size());
  dy.pDynamicStates = dyn.data();

  // One write mask per colour attachment of the subpass (none: depth only).
  VkPipelineVertexInputStateCreateInfo no_vertices{};
  no_vertices.sType = VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO;
  VkShaderModule vs = vert->get();
  VkPipelineLayout pipeline_layout = layout_.get();
  const VkPipelineVertexInputStateCreateInfo* vertex_input = &vi;
  auto graphics = [&](VkShaderModule fs, VkRenderPass pass, uint32_t subpass,
                      std::span<const VkColorComponentFlags> colour_masks, VkCompareOp compare, bool depth_write,
                      UniquePipeline& out) -> Status {
    ds.depthCompareOp = compare;
    ds.depthWriteEnable = depth_write ? VK_TRUE : VK_FALSE;
    for (size_t i = 0; i < colour_masks.size(); ++i) cba[i].colorWriteMask = colour_masks[i];
    std::array<VkPipelineShaderStageCreateInfo, 2> stages{};
    stages[0] = {};
    stages[0].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    stages[0].stage = VK_SHADER_STAGE_VERTEX_BIT;
    stages[0].module = vs;
    stages[0].pName = "main";
    stages[1] = {};
    stages[1].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    stages[1].stage = VK_SHADER_STAGE_FRAGMENT_BIT;
    stages[1].module = fs;
    stages[1].pName = "main";
    cb.attachmentCount = static_cast<uint32_t>(colour_masks.size());
    cb.pAttachments = colour_masks.empty() ? nullptr : cba.data();
    VkGraphicsPipelineCreateInfo gi{};
    gi.sType = VK_STRUCTURE_TYPE_GRAPHICS_PIPELINE_CREATE_INFO;
    gi.stageCount = 2;
    gi.pStages = stages.data();
    gi.pVertexInputState = vertex_input;
    gi.pInputAssemblyState = &ia;
    gi.pViewportState = &vp;
    gi.pRasterizationState = &rs;
    gi.pMultisampleState = &ms;
    gi.pDepthStencilState = &ds;
    gi.pColorBlendState = &cb;
    gi.pDynamicState = &dy;
    gi.layout = pipeline_layout;
    gi.renderPass = pass;
    gi.subpass = subpass;
    VkPipeline p = VK_NULL_HANDLE;
    TS_VK_TRY(vkCreateGraphicsPipelines(device, VK_NULL_HANDLE, 1, &gi, nullptr, &p));
    out = UniquePipeline(device, p);
    return ok_status();
  };
  // Reversed Z: nearer is larger. The pre-pass resolves visibility and writes each pixel's owner (GREATER: the
  // first-drawn of equally near fragments keeps it); the shading draw keeps only the fragments whose depth
  // equals the winner's (bit-identical through `invariant gl_Position`) and, in scene.frag, whose mesh owns
  // the pixel.
  constexpr VkColorComponentFlags kRgba =
      VK_COLOR_COMPONENT_R_BIT | VK_COLOR_COMPONENT_G_BIT | VK_COLOR_COMPONENT_B_BIT | VK_COLOR_COMPONENT_A_BIT;
  constexpr std::array<VkColorComponentFlags, 1> kOwnerMask{VK_COLOR_COMPONENT_R_BIT};
  // The same mask for both attachments (without the independentBlend feature they must be identical); the
  // metadata attachment simply has no B and A to write.
  constexpr std::array<VkColorComponentFlags, 2> kShadingMasks{kRgba, kRgba};
  TS_TRY(graphics(prepass->get(), main_pass_.get(), 0, kOwnerMask, VK_COMPARE_OP_GREATER, true, prepass_pipeline_));
  TS_TRY(graphics(frag->get(), main_pass_.get(), 1, kShadingMasks, VK_COMPARE_OP_EQUAL, false, main_pipeline_));
  TS_TRY(graphics(wide_frag->get(), wide_pass_.get(), 0, {}, VK_COMPARE_OP_GREATER, true, wide_pipeline_));
  if (ground_) {
    // The ground (ground.vert: one quad, no vertex buffers) in both subpasses, like the meshes.
    auto ground_vert = make_module(ctx, compiler, {"ground.vert", ShaderStage::kVertex, {}});
    if (!ground_vert) return ground_vert.error();
    auto ground_pre = make_module(ctx, compiler, {"ground.frag", ShaderStage::kFragment, {"PREPASS"}});
    if (!ground_pre) return ground_pre.error();
    std::vector<std::string> ground_defines;
    if (ground_->reference()) ground_defines.push_back("GROUND_REFERENCE");
    auto ground_frag = make_module(ctx, compiler, {"ground.frag", ShaderStage::kFragment, ground_defines});
    if (!ground_frag) return ground_frag.error();
    vs = ground_vert->get();
    vertex_input = &no_vertices;
    pipeline_layout = ground_layout_.get();
    TS_TRY(graphics(ground_pre->get(), main_pass_.get(), 0, kOwnerMask, VK_COMPARE_OP_GREATER, true,
                    ground_prepass_pipeline_));
    TS_TRY(
        graphics(ground_frag->get(), main_pass_.get(), 1, kShadingMasks, VK_COMPARE_OP_EQUAL, false, ground_pipeline_));
  }

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
  TS_TRY(compute(reduce->get(), meta_reduce_pipeline_));
  TS_TRY(compute(comp->get(), compact_pipeline_));
  TS_TRY(compute(to_host->get(), compact_to_host_pipeline_));
  return ok_status();
}

void ScenePasses::bind_texture_table(VkBuffer table) {
  if (table == texture_table_) return;
  const VkDescriptorBufferInfo info{table, 0, VK_WHOLE_SIZE};
  VkWriteDescriptorSet w{};
  w.sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
  w.dstSet = set_;
  w.dstBinding = gpu::kBindingTextures;
  w.descriptorCount = 1;
  w.descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
  w.pBufferInfo = &info;
  vkUpdateDescriptorSets(device_, 1, &w, 0, nullptr);
  texture_table_ = table;
}

void ScenePasses::record(VkCommandBuffer cmd, const FrameRecording& frame) const {
  const uint32_t main_count = std::min(frame.main_count, frame.draw_count);
  const uint32_t wide_first = std::min(frame.wide_first, frame.draw_count);
  // The fields of the frame uniforms that describe these passes (the caller fills the rest before record()).
  auto* fu = scene_.frame_uniforms().as<gpu::FrameUniforms>();
  fu->flags.x = frame.feedback ? (fu->flags.x | gpu::kFlagFeedback) : (fu->flags.x & ~gpu::kFlagFeedback);
  fu->view = {options_.debug_view, options_.width, frame.mesh_count, 0};
  if (timestamps_) {
    vkCmdResetQueryPool(cmd, timestamps_.get(), 0, kTimestampCount);
    vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, timestamps_.get(), 0);
  }

  // The previous submission's compaction wrote the sparse metadata and the list counter; this frame's fragment
  // atomics and the counter reset come after it (submission order + this barrier).
  memory_barrier(
      cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_SHADER_READ_BIT,
      VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
      VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT);
  // The list this frame compacts into: straight into the host-visible read-back list when a streaming cycle
  // is about to start (compact.comp with COMPACT_TO_HOST), else the device-local one.
  const GpuBuffer& list = frame.read_back_list ? scene_.readback() : scene_.compacted();
  if (frame.feedback) vkCmdFillBuffer(cmd, list.handle(), 0, sizeof(gpu::CompactListHeader), 0);
  if (ground_) ground_->record_needs_clear(cmd);

  auto begin_pass = [&](VkRenderPass pass, VkFramebuffer fb, uint32_t w, uint32_t h, bool main) {
    std::array<VkClearValue, 4> clears{};
    // Sky colour in linear light (the attachment is sRGB); the id view clears to 0 = "no mesh". Depth 0 is
    // "infinitely far" with reversed Z; owner 0 is "no mesh".
    clears[0].color = {{0.45f, 0.6f, 0.8f, 1.0f}};
    if (options_.debug_view == gpu::kDebugViewMeshId) clears[0].color = {{0.0f, 0.0f, 0.0f, 1.0f}};
    clears[main ? 1 : 0].depthStencil = {0.0f, 0};
    clears[2].color.uint32[0] = 0;
    clears[3].color.uint32[0] = 0;  // metadata: mesh id + 1 = 0, "no mesh" (meta_reduce skips the pixel)
    VkRenderPassBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO;
    bi.renderPass = pass;
    bi.framebuffer = fb;
    bi.renderArea = {{0, 0}, {w, h}};
    bi.clearValueCount = main ? 4 : 1;
    bi.pClearValues = clears.data();
    vkCmdBeginRenderPass(cmd, &bi, VK_SUBPASS_CONTENTS_INLINE);
    const VkViewport viewport{0, 0, static_cast<float>(w), static_cast<float>(h), 0, 1};
    const VkRect2D scissor{{0, 0}, {w, h}};
    vkCmdSetViewport(cmd, 0, 1, &viewport);
    vkCmdSetScissor(cmd, 0, 1, &scissor);
  };
  // Draws [first, first + count) of the indirect list in one multi-draw indirect call (seed 001: few calls).
  auto draw = [&](VkPipeline pipeline, const gpu::PassConstants& pc, uint32_t first, uint32_t count) {
    if (count == 0) return;
    vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, layout_.get(), 0, 1, &set_, 0, nullptr);
    vkCmdPushConstants(cmd, layout_.get(), kAllStages, 0, sizeof pc, &pc);
    const std::array<VkBuffer, 2> vbs{scene_.vertices().handle(), scene_.vertex_mesh().handle()};
    const std::array<VkDeviceSize, 2> offsets{0, 0};
    vkCmdBindVertexBuffers(cmd, 0, 2, vbs.data(), offsets.data());
    vkCmdBindIndexBuffer(cmd, scene_.indices().handle(), 0, VK_INDEX_TYPE_UINT32);
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, pipeline);
    vkCmdDrawIndexedIndirect(cmd, scene_.indirect().handle(),
                             VkDeviceSize{first} * sizeof(VkDrawIndexedIndirectCommand), count,
                             sizeof(VkDrawIndexedIndirectCommand));
  };
  // Main pass: the pre-pass (depth + owner id), then the shading subpass over the same draws.
  // The ground (GroundPages) after the meshes in each subpass: one quad, its own set 1.
  auto draw_ground = [&](VkPipeline pipeline) {
    if (!ground_) return;
    const std::array<VkDescriptorSet, 2> sets{set_, ground_set_};
    vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, ground_layout_.get(), 0, 2, sets.data(), 0, nullptr);
    vkCmdPushConstants(cmd, ground_layout_.get(), kAllStages, 0, sizeof frame.main, &frame.main);
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, pipeline);
    vkCmdDraw(cmd, 6, 1, 0, 0);
  };
  begin_pass(main_pass_.get(), main_fb_.get(), options_.width, options_.height, true);
  draw(prepass_pipeline_.get(), frame.main, 0, main_count);
  draw_ground(ground_prepass_pipeline_.get());
  vkCmdNextSubpass(cmd, VK_SUBPASS_CONTENTS_INLINE);
  draw(main_pipeline_.get(), frame.main, 0, main_count);
  draw_ground(ground_pipeline_.get());
  vkCmdEndRenderPass(cmd);
  if (ground_ && ground_->writes_needs()) {
    memory_barrier(cmd, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT, VK_PIPELINE_STAGE_HOST_BIT,
                   VK_ACCESS_HOST_READ_BIT);
  }
  if (timestamps_) vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, timestamps_.get(), 1);
  timestamps_written_ = 2;
  if (!frame.feedback) return;
  // Wide pass: the meshes entirely outside the viewport's frustum (seed 000 §3.2: W = 1 for meshes that lie
  // outside of the viewport).
  begin_pass(wide_pass_.get(), wide_fb_.get(), options_.wide_width, options_.wide_height, false);
  draw(wide_pipeline_.get(), frame.wide, wide_first, frame.draw_count - wide_first);
  vkCmdEndRenderPass(cmd);
  if (timestamps_) vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, timestamps_.get(), 2);

  // The main pass's metadata, per pixel, summed per mesh (the render pass's external dependencies make its
  // owner ids and metadata visible here). Its atomics and the wide pass's commute.
  vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, layout_.get(), 0, 1, &set_, 0, nullptr);
  vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, meta_reduce_pipeline_.get());
  const uint32_t runs = (options_.width + gpu::kMetaReduceRun - 1) / gpu::kMetaReduceRun * options_.height;
  vkCmdDispatch(cmd, (runs + gpu::kMetaReduceGroup - 1) / gpu::kMetaReduceGroup, 1, 1);
  // Compaction reads what the wide pass's fragment shader and meta_reduce wrote and the cleared counter. One
  // invocation per mesh drawn this frame (the only meshes that can have metadata), not per mesh of the scene.
  memory_barrier(
      cmd,
      VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
      VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
      VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
  vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE,
                    frame.read_back_list ? compact_to_host_pipeline_.get() : compact_pipeline_.get());
  const uint32_t groups = (frame.mesh_count + gpu::kCompactWorkgroupSize - 1) / gpu::kCompactWorkgroupSize;
  if (groups > 0) vkCmdDispatch(cmd, groups, 1, 1);
  if (frame.read_back_list) {
    memory_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT, VK_PIPELINE_STAGE_HOST_BIT,
                   VK_ACCESS_HOST_READ_BIT);
  }
  if (timestamps_) vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, timestamps_.get(), 3);
  timestamps_written_ = 4;
}

PassTimes ScenePasses::read_pass_times() const {
  PassTimes t;
  if (!timestamps_) return t;
  std::array<uint64_t, kTimestampCount> v{};
  // Only the queries the last frame wrote (feedback off: the rest stay zero, those passes took no time).
  if (timestamps_written_ < 2) return t;
  if (vkGetQueryPoolResults(device_, timestamps_.get(), 0, timestamps_written_, sizeof v, v.data(), sizeof(uint64_t),
                            VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT) != VK_SUCCESS)
    return t;
  auto ms = [&](int a, int b) {
    return v[b] > v[a] ? static_cast<double>(v[b] - v[a]) * timestamp_period_ns_ * 1e-6 : 0.0;
  };
  t.main_ms = ms(0, 1);
  t.wide_ms = ms(1, 2);
  t.compact_ms = ms(2, 3);
  return t;
}

}  // namespace texstream::render
