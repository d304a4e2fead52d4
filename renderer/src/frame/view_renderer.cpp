#include "texstream/render/frame/view_renderer.hpp"

#include <chrono>
#include <cstring>

#include "texstream/render/scene/camera.hpp"
#include "texstream/render/frame/frame_capture.hpp"
#include "texstream/render/frame/frame_constants.hpp"
#include "texstream/render/scene/scene_gpu.hpp"
#include "texstream/render/frame/scene_passes.hpp"
#include "texstream/render/vulkan/shader_compiler.hpp"
#include "texstream/render/cache/texture_cache.hpp"
#include "texstream/stream/texture_states.hpp"
#include "texstream/render/vulkan/vk_check.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

namespace texstream::render {

namespace {

using Clock = std::chrono::steady_clock;
// Same as renderer_app.cpp: the wide metadata pass renders at 1/4 of the viewport per axis.
constexpr uint32_t kWidePassDivisor = 4;
// Nothing is streamed here: a small cache image is enough to give the shaders (and the LOD probe) a texture.
constexpr uint32_t kCacheLayers = 2;
constexpr uint64_t kStagingBytes = 1u << 20;

// Inverse of kMeshIdHashMul modulo 2^24 (Newton's iteration x <- x (2 - a x) doubles the correct low bits).
constexpr uint32_t inverse_mod_2_24(uint32_t a) {
  uint32_t x = a;  // correct to 3 bits for odd a
  for (int i = 0; i < 5; ++i) x = (x * (2u - a * x)) & 0xffffffu;
  return x;
}
constexpr uint32_t kMeshIdHashInverse = inverse_mod_2_24(gpu::kMeshIdHashMul);
static_assert(((kMeshIdHashInverse * gpu::kMeshIdHashMul) & 0xffffffu) == 1u);

}  // namespace

int64_t decode_mesh_id(uint8_t r, uint8_t g, uint8_t b) {
  const uint32_t code = static_cast<uint32_t>(r) | (static_cast<uint32_t>(g) << 8) | (static_cast<uint32_t>(b) << 16);
  if (code == 0) return -1;
  return static_cast<int64_t>(((code * kMeshIdHashInverse) & 0xffffffu)) - 1;
}

struct ViewRenderer::Impl {
  Config cfg;
  ViewRendererOptions options;
  SceneData scene;
  std::unique_ptr<VulkanContext> ctx;
  std::unique_ptr<TextureStates> states;
  std::unique_ptr<TextureCache> cache;
  std::unique_ptr<SceneGpu> gpu;
  std::unique_ptr<ShaderCompiler> compiler;
  std::unique_ptr<ScenePasses> passes;
  std::unique_ptr<FrameCapture> capture;
  std::unique_ptr<BroadPhase> broad_phase;
  UniqueCommandPool pool;
  VkCommandBuffer cmd = VK_NULL_HANDLE;
  UniqueFence fence;
  std::vector<uint32_t> visible;
  std::vector<uint32_t> new_textures;
  uint64_t serial = 0;
};

ViewRenderer::ViewRenderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

ViewRenderer::~ViewRenderer() {
  if (impl_ && impl_->ctx) vkDeviceWaitIdle(impl_->ctx->device());  // nothing to do about a failure here
}

const SceneData& ViewRenderer::scene() const { return impl_->scene; }
uint32_t ViewRenderer::validation_errors() const { return impl_->ctx->validation_errors(); }
bool ViewRenderer::probe_is_anisotropic() const { return impl_->passes->probe_is_anisotropic(); }

Result<std::unique_ptr<ViewRenderer>> ViewRenderer::create(const Config& cfg, SceneData scene,
                                                            const ViewRendererOptions& options) {
  auto impl = std::make_unique<Impl>();
  Impl& m = *impl;
  m.cfg = cfg;
  m.options = options;
  m.scene = std::move(scene);
  if (options.scene_offset != std::array<double, 3>{}) {
    TS_TRY(m.scene.make_loaded());  // the records are edited: an opened (mapped) scene is copied first
    for (auto& mesh : m.scene.meshes.meshes)
      for (int a = 0; a < 3; ++a) mesh.origin[a] += options.scene_offset[a];
  }

  VulkanContextOptions vo;
  vo.device_substring = cfg.render.device;
  vo.validation = cfg.render.validation;
  vo.need_bc1 = m.scene.manifest.texture_format == TexelFormat::kBc1;
  auto ctx = VulkanContext::create(vo);
  if (!ctx) return ctx.error();
  m.ctx = std::move(*ctx);

  m.states = std::make_unique<TextureStates>(m.scene.shapes());
  TextureCacheOptions co;
  co.format = m.scene.manifest.texture_format;
  co.layer_extent = static_cast<uint32_t>(cfg.cache.layer_extent_px);
  co.layers = kCacheLayers;
  co.staging_bytes = kStagingBytes;
  auto cache = TextureCache::create(*m.ctx, co, m.scene, *m.states);
  if (!cache) return cache.error();
  m.cache = std::move(*cache);
  auto gpu = SceneGpu::create(*m.ctx, m.scene, options.stage_geometry);
  if (!gpu) return gpu.error();
  m.gpu = std::make_unique<SceneGpu>(std::move(*gpu));
  m.compiler = std::make_unique<ShaderCompiler>(ShaderCompiler::default_source_dir(),
                                                ShaderCompiler::default_cache_dir());
  ScenePassesOptions po;
  po.width = static_cast<uint32_t>(cfg.render.width_px);
  po.height = static_cast<uint32_t>(cfg.render.height_px);
  po.wide_width = std::max(16u, po.width / kWidePassDivisor);
  po.wide_height = std::max(16u, po.height / kWidePassDivisor);
  po.debug_view = gpu_debug_view(cfg.render.debug_view);
  po.lod_probe = options.lod_probe;
  po.probe_anisotropy = static_cast<float>(cfg.stream.max_anisotropy);
  po.timestamps = options.timestamps;
  auto passes = ScenePasses::create(*m.ctx, *m.compiler, po, *m.gpu, *m.cache);
  if (!passes) return passes.error();
  m.passes = std::move(*passes);
  auto capture = FrameCapture::create(*m.ctx, po.width, po.height);
  if (!capture) return capture.error();
  m.capture = std::make_unique<FrameCapture>(std::move(*capture));
  m.broad_phase = BroadPhase::for_scene(m.scene);

  VkDevice device = m.ctx->device();
  VkCommandPoolCreateInfo pci{};
  pci.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
  pci.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pci.queueFamilyIndex = m.ctx->queue_family();
  VkCommandPool pool = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateCommandPool(device, &pci, nullptr, &pool));
  m.pool = UniqueCommandPool(device, pool);
  VkCommandBufferAllocateInfo ai{};
  ai.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
  ai.commandPool = pool;
  ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  ai.commandBufferCount = 1;
  TS_VK_TRY(vkAllocateCommandBuffers(device, &ai, &m.cmd));
  VkFenceCreateInfo fci{};
  fci.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
  VkFence fence = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateFence(device, &fci, nullptr, &fence));
  m.fence = UniqueFence(device, fence);
  return std::unique_ptr<ViewRenderer>(new ViewRenderer(std::move(impl)));
}

Result<ViewResult> ViewRenderer::render(const CameraPose& pose, const ViewRequest& request) {
  Impl& m = *impl_;
  const auto& r = m.cfg.render;
  const CameraLens lens{r.fov_y_deg, r.offscreen_fov_y_deg,
                        static_cast<double>(r.width_px) / static_cast<double>(r.height_px), r.near_m, r.far_m};
  const Camera cam = make_camera(pose, lens);
  ViewResult out;
  out.width = m.passes->options().width;
  out.height = m.passes->options().height;

  const auto t0 = Clock::now();
  // The wide frustum for both passes, then split by the viewport's: each pass draws only what it can see.
  m.broad_phase->query(Frustum::from_matrix(cam.wide_proj * cam.view), cam.position, m.visible, &out.broad_phase);
  ViewportSplit split =
      m.broad_phase->split_by_viewport(Frustum::from_matrix(cam.proj * cam.view), cam.position, m.visible);
  out.submitted = m.visible.size();
  FrameRecording rec;
  rec.main = main_pass_constants(cam);
  rec.wide = wide_pass_constants(cam, r.fov_y_deg, r.offscreen_fov_y_deg, out.height, m.passes->options().wide_height);
  if (m.options.drop_unsampled) {
    const auto& po = m.passes->options();
    const uint32_t bits = m.ctx->properties().limits.subPixelPrecisionBits;
    split = m.broad_phase->drop_unsampled(
        SampleGrid::from_columns(rec.main.view_proj.m, po.width, po.height, bits),
        SampleGrid::from_columns(rec.wide.view_proj.m, po.wide_width, po.wide_height, bits), cam.position,
        m.visible, split);
  }
  out.unsampled = out.submitted - m.visible.size();
  out.broad_phase_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();

  // As the frame loop does: meshes drawn for the first time are checked and uploaded in this submission.
  m.new_textures.clear();
  TS_TRY(m.gpu->make_resident(m.scene, m.visible, &m.new_textures));
  TS_TRY(m.cache->prepare_textures(m.new_textures));
  m.gpu->write_draws(m.scene, m.visible, cam.position, split, rec);
  out.main_meshes = rec.main_meshes;
  out.wide_meshes = rec.wide_meshes;
  out.main_draws = rec.main_count;
  out.wide_draws = rec.draw_count - rec.wide_first;
  rec.feedback = request.feedback;
  rec.read_back_list = request.feedback && request.read_back;
  *m.gpu->frame_uniforms.as<gpu::FrameUniforms>() = frame_uniforms(
      cam, m.cfg, m.gpu->mesh_count, m.gpu->compact_capacity, m.cache->layer_extent(), m.cache->mip_levels());
  if (m.options.lod_probe) {
    auto bytes = m.passes->probe().bytes();
    std::memset(bytes.data(), 0, bytes.size());
  }

  VkDevice device = m.ctx->device();
  TS_VK_TRY(vkResetCommandBuffer(m.cmd, 0));
  VkCommandBufferBeginInfo bi{};
  bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
  bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  TS_VK_TRY(vkBeginCommandBuffer(m.cmd, &bi));
  m.cache->record_uploads(m.cmd, ++m.serial);
  TS_TRY(m.gpu->record_uploads(m.scene, m.cmd));
  m.passes->record(m.cmd, rec);
  if (request.capture) m.capture->record(m.cmd, m.passes->colour().handle());
  TS_VK_TRY(vkEndCommandBuffer(m.cmd));
  VkSubmitInfo si{};
  si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
  si.commandBufferCount = 1;
  si.pCommandBuffers = &m.cmd;
  VkFence fence = m.fence.get();
  TS_VK_TRY(vkResetFences(device, 1, &fence));
  const auto t1 = Clock::now();
  TS_VK_TRY(vkQueueSubmit(m.ctx->queue(), 1, &si, fence));
  TS_VK_TRY(vkWaitForFences(device, 1, &fence, VK_TRUE, UINT64_MAX));
  out.gpu_ms = std::chrono::duration<double, std::milli>(Clock::now() - t1).count();
  m.cache->on_submission_complete(m.serial);
  out.pass_times = m.passes->read_pass_times();

  if (rec.read_back_list) {
    const auto* header = m.gpu->readback.as<gpu::CompactListHeader>();
    out.list_count = header->count;
    const uint32_t used = std::min(header->count, m.gpu->compact_capacity);
    const auto* entries = reinterpret_cast<const gpu::CompactEntry*>(m.gpu->readback.bytes().data() +
                                                                     sizeof(gpu::CompactListHeader));
    out.entries.assign(entries, entries + used);
  }
  if (request.capture) {
    const auto px = m.capture->pixels();
    const size_t n = static_cast<size_t>(out.width) * out.height * 4;
    out.rgba.resize(n);
    std::memcpy(out.rgba.data(), px.data(), std::min(n, px.size()));
  }
  if (m.options.lod_probe) {
    const auto* p = m.passes->probe().as<gpu::LodProbeSample>();
    out.probe.assign(p, p + static_cast<size_t>(out.width) * out.height);
  }
  return out;
}

}  // namespace texstream::render
