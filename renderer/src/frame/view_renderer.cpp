#include "texstream/render/frame/view_renderer.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>

#include "texstream/render/frame/frame_capture.hpp"
#include "texstream/render/frame/frame_plan.hpp"
#include "texstream/render/frame/render_stack.hpp"
#include "texstream/render/scene/camera.hpp"
#include "texstream/render/scene/scene_gpu.hpp"

namespace texstream::render {

namespace {

using Clock = std::chrono::steady_clock;
// Nothing is streamed here: a small cache image is enough to give the shaders (and the LOD probe) a texture.
constexpr uint32_t kCacheLayers = 2;
constexpr uint32_t kCacheLayerExtent = 512;
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
  SceneData scene;  // before the stack, which reads it until it is gone
  std::unique_ptr<RenderStack> stack;
};

ViewRenderer::ViewRenderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

ViewRenderer::~ViewRenderer() = default;

const SceneData& ViewRenderer::scene() const { return impl_->scene; }
uint32_t ViewRenderer::validation_errors() const { return impl_->stack->context().validation_errors(); }
bool ViewRenderer::probe_is_anisotropic() const { return impl_->stack->passes().probe_is_anisotropic(); }

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

  RenderStackOptions so;
  so.vulkan.device_substring = cfg.render.device;
  so.vulkan.validation = cfg.render.validation;
  so.vulkan.need_bc = !m.scene.manifest.texture_format || is_block_compressed(*m.scene.manifest.texture_format);
  so.cache.layer_extent =
      cfg.cache.layer_extent_px ? static_cast<uint32_t>(cfg.cache.layer_extent_px) : kCacheLayerExtent;
  so.cache.layers = kCacheLayers;
  so.cache.staging_bytes = kStagingBytes;
  so.stage_geometry = options.stage_geometry;
  auto passes = scene_passes_options(cfg);
  if (!passes) return passes.error();
  ScenePassesOptions& po = so.passes;
  po = *passes;
  po.lod_probe = options.lod_probe;
  po.probe_anisotropy = static_cast<float>(cfg.stream.max_anisotropy);
  po.timestamps = options.timestamps;
  auto stack = RenderStack::create(m.scene, so);
  if (!stack) return stack.error();
  m.stack = std::move(*stack);
  return std::unique_ptr<ViewRenderer>(new ViewRenderer(std::move(impl)));
}

Result<ViewResult> ViewRenderer::render(const CameraPose& pose, const ViewRequest& request) {
  Impl& m = *impl_;
  RenderStack& stack = *m.stack;
  const auto& r = m.cfg.render;
  const CameraLens lens{r.fov_y_deg, r.offscreen_fov_y_deg,
                        static_cast<double>(r.width_px) / static_cast<double>(r.height_px), r.near_m, r.far_m};
  const Camera cam = make_camera(pose, lens);
  ViewResult out;
  out.width = stack.passes().options().width;
  out.height = stack.passes().options().height;

  // The frame loop's plan (frame_plan.hpp): meshes drawn for the first time are checked and uploaded in this
  // submission.
  const auto t0 = Clock::now();
  FramePlanOptions fo;
  fo.drop_unsampled = m.options.drop_unsampled;
  fo.stats = &out.broad_phase;
  fo.step = [&](const char* name) {
    if (std::strcmp(name, "broad_phase") == 0)
      out.broad_phase_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  };
  auto plan = plan_frame(stack, cam, m.cfg, fo);
  if (!plan) return plan.error();
  FrameRecording& rec = plan->rec;
  out.submitted = plan->submitted;
  out.unsampled = plan->unsampled;
  out.main_meshes = rec.main_meshes;
  out.wide_meshes = rec.wide_meshes;
  out.main_draws = rec.main_count;
  out.wide_draws = rec.draw_count - rec.wide_first;
  rec.feedback = request.feedback;
  rec.read_back_list = request.feedback && request.read_back;
  if (m.options.lod_probe) {
    auto bytes = stack.passes().probe().bytes();
    std::memset(bytes.data(), 0, bytes.size());
  }

  Submission sub;
  sub.passes = &rec;
  sub.capture = request.capture;
  TS_TRY(stack.submit(sub));
  out.gpu_ms = stack.last_gpu_ms();
  out.pass_times = stack.passes().read_pass_times();

  const SceneGpu& gpu = stack.scene_gpu();
  if (rec.read_back_list) {
    out.list_count = gpu.read_back_count();
    const auto entries = gpu.read_back_entries();
    out.entries.assign(entries.begin(), entries.end());
  }
  if (request.capture) {
    const auto px = stack.capture().pixels();
    const size_t n = static_cast<size_t>(out.width) * out.height * 4;
    out.rgba.resize(n);
    std::memcpy(out.rgba.data(), px.data(), std::min(n, px.size()));
  }
  if (m.options.lod_probe) {
    const auto* p = stack.passes().probe().as<gpu::LodProbeSample>();
    out.probe.assign(p, p + static_cast<size_t>(out.width) * out.height);
  }
  return out;
}

}  // namespace texstream::render
