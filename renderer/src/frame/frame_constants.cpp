#include "texstream/render/frame/frame_constants.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>

namespace texstream::render {

gpu::PassConstants main_pass_constants(const Camera& cam) {
  gpu::PassConstants pc{};
  const glm::mat4 vp = cam.proj * cam.view;
  std::memcpy(pc.view_proj.m, &vp[0][0], sizeof pc.view_proj.m);
  pc.pass = {0.0f, 1.0f, 2.0f, 2.0f};  // no lod offset, W as computed, nothing is "outside the viewport"
  return pc;
}

gpu::PassConstants wide_pass_constants(const Camera& cam, double fov_y_deg, double wide_fov_y_deg, uint32_t height,
                                       uint32_t wide_height) {
  const double t_view = std::tan(fov_y_deg * std::numbers::pi / 360.0);
  const double t_wide = std::tan(wide_fov_y_deg * std::numbers::pi / 360.0);
  // One wide-pass pixel spans `ratio` viewport pixels per axis: its mip level is log2(ratio) coarser than the
  // viewport would need, and it stands for ratio^2 viewport pixels of W = 1 each (seed 000 §3.2).
  const double ratio = (t_wide / wide_height) / (t_view / height);
  gpu::PassConstants pc{};
  const glm::mat4 vp = cam.wide_proj * cam.view;
  std::memcpy(pc.view_proj.m, &vp[0][0], sizeof pc.view_proj.m);
  const auto bound = static_cast<float>(t_view / t_wide);  // the viewport's |ndc| extent inside the wide pass
  pc.pass = {static_cast<float>(-std::log2(ratio)), static_cast<float>(ratio * ratio), bound, bound};
  return pc;
}

gpu::FrameUniforms frame_uniforms(const Camera& cam, const Config& cfg, uint32_t mesh_count, uint32_t compact_capacity,
                                  const std::array<uint32_t, 4>& cache_layer_extents) {
  gpu::FrameUniforms fu{};
  const auto a_m = static_cast<float>(cfg.stream.max_anisotropy);
  fu.camera_forward = {cam.forward.x, cam.forward.y, cam.forward.z, 0.0f};
  // A_s = A_m / 2 (seed 000 §3.2), at least one tap.
  fu.params = {a_m, std::max(1.0f, std::floor(a_m / 2.0f)), static_cast<float>(cfg.stream.foreground_distance_m),
               static_cast<float>(cfg.render.headlight_ambient)};
  const double tau_fixed = std::min(cfg.stream.tau * gpu::kWeightFixedScale, 4294967295.0);
  uint32_t blend = 0;  // stream.colormap_blend = false: sampled colour only
  if (cfg.stream.colormap_blend) {
    blend = gpu::kFlagColormapBlend;
    if (cfg.stream.blend == BlendMode::kSeed) blend |= gpu::kFlagBlendSeed;
    if (cfg.stream.blend == BlendMode::kConvergeLinear) blend |= gpu::kFlagBlendLinear;
    const auto exponent = static_cast<uint32_t>(std::clamp<int64_t>(cfg.stream.blend_exponent, 1, 8));
    blend |= exponent << gpu::kBlendExponentShift;
  }
  fu.flags = {blend | gpu::kFlagLighting, mesh_count, static_cast<uint32_t>(std::ceil(tau_fixed)), compact_capacity};
  fu.cache = {cache_layer_extents[0], cache_layer_extents[1], cache_layer_extents[2], cache_layer_extents[3]};
  return fu;
}

}  // namespace texstream::render
