#pragma once
// CPU twins of shaders/mip_math.glsl: the mip level under anisotropic filtering (Hollemeersch et al., seed 000
// §3.2) and the per-fragment weight (Eq. 1-3). Used by tests to pin the formula and by the CPU to reason about
// what the shader will ask for.
#include <algorithm>
#include <cmath>

namespace texstream::render {

struct AnisoLod {
  float lod;   // log2(p_max / N)
  float taps;  // N = min(ceil(p_max / p_min), max_aniso), at least 1
};

// dx = (du/dx, dv/dx), dy = (du/dy, dv/dy) in texels of mip 0 per pixel.
inline AnisoLod anisotropic_lod(float dudx, float dvdx, float dudy, float dvdy, float max_aniso) {
  const float px = std::sqrt(dudx * dudx + dvdx * dvdx);
  const float py = std::sqrt(dudy * dudy + dvdy * dvdy);
  const float pmax = std::max(px, py);
  const float pmin = std::min(px, py);
  // As the shader: ratios within 1/256 above an integer count as it (float noise must not double N).
  float n = pmin > 0.0f ? std::min(std::ceil(pmax / pmin - 1.0f / 256.0f), max_aniso) : max_aniso;
  n = std::max(n, 1.0f);
  float lod = pmax > 0.0f ? std::log2(pmax / n) : -64.0f;
  // As the shader: non-finite footprints ask for the coarsest level (64 clamps to M_max), never NaN.
  if (std::isnan(lod) || std::isinf(lod)) lod = std::isinf(lod) && lod < 0.0f ? -64.0f : 64.0f;
  return {lod, std::isnan(n) ? max_aniso : n};
}

// Eq. 2 with c_w = min(w_clip / D, 1): w_clip = 1 / gl_FragCoord.w is the view depth in metres; D is the
// foreground distance (see shaders/mip_math.glsl for why the paper's literal form needs a length scale).
inline float distance_weight(float w_clip_m, float foreground_distance_m) {
  const float c_w = std::clamp(w_clip_m / foreground_distance_m, 0.0f, 1.0f);
  const float a = 1.0f - c_w;
  return a * a * a * a;
}

// Eq. 1 and 3: W = 1 + 8 w_d + 8 w_m, w_m = min(M / M_max, 1).
inline float fragment_weight(float w_d, float displayed_mip, float mip_max) {
  const float w_m = mip_max > 0.0f ? std::min(displayed_mip / mip_max, 1.0f) : 0.0f;
  return 1.0f + 8.0f * w_d + 8.0f * w_m;
}

}  // namespace texstream::render
