// Mip level under anisotropic filtering (Hollemeersch et al., as used by seed 000 §3.2). The C++ twin is
// renderer/include/texstream/render/frame/mip_math.hpp; tests/unit/render_mip_math_test.cpp pins its values.
// dx, dy: texture-coordinate derivatives along screen x and y, in texels of mip 0.
struct AnisoLod {
  float lod;   // log2(p_max / N)
  float taps;  // N = min(ceil(p_max / p_min), max_aniso), at least 1
};

// The part of the footprint both of a fragment's levels share (sampling with A_s, metadata with A_m): the
// major axis and the rounded axis ratio, computed once per fragment (scene.frag). The C++ twin's
// anisotropic_lod() is aniso_footprint() followed by anisotropic_lod_of(), in the same order.
struct AnisoFootprint {
  float pmax;
  float pmin;
  float ratio;  // ceil(p_max / p_min) (see anisotropic_lod_of); only meaningful when p_min > 0
};

AnisoFootprint aniso_footprint(vec2 dx, vec2 dy) {
  float px = length(dx);
  float py = length(dy);
  AnisoFootprint f;
  f.pmax = max(px, py);
  f.pmin = min(px, py);
  // ceil() of a ratio that rounding pushed just above an integer would double N (and drop the level by one) for
  // an isotropic footprint whose two axes differ in the last bits: ratios within 1/256 of an integer count as it.
  f.ratio = f.pmin > 0.0 ? ceil(f.pmax / f.pmin - 1.0 / 256.0) : 0.0;
  return f;
}

AnisoLod anisotropic_lod_of(AnisoFootprint f, float max_aniso) {
  // p_min = 0 (a degenerate footprint) is infinitely anisotropic: N = max_aniso.
  float n = f.pmin > 0.0 ? min(f.ratio, max_aniso) : max_aniso;
  n = max(n, 1.0);
  AnisoLod r;
  // p_max = 0 (no change across the pixel) is infinite magnification; -64 stands for it and is clamped later.
  r.lod = f.pmax > 0.0 ? log2(f.pmax / n) : -64.0;
  // Non-finite derivatives (uv blowing up at a degenerate or near-plane triangle edge): ask for the coarsest
  // level rather than let a NaN reach clamp() (undefined) or the fixed-point conversion. 64 clamps to M_max.
  if (isnan(r.lod) || isinf(r.lod)) r.lod = isinf(r.lod) && r.lod < 0.0 ? -64.0 : 64.0;
  r.taps = isnan(n) ? max_aniso : n;
  return r;
}

// Eq. 2 with a stated unit: c_w = min(w_clip / D, 1). gl_FragCoord.w is 1 / w_clip and w_clip is the view-space
// depth in metres, so the paper's literal min(1 / gl_FragCoord.w, 1) saturates at 1 m and w_d would vanish for
// every fragment of a city. We divide by a foreground distance D (FrameUniforms.params.z) so that w_d falls from
// 1 at the camera to 0 at D metres.
float distance_weight(float frag_coord_w, float foreground_distance_m) {
  // gl_FragCoord.w > 0 for every fragment that survived clipping; the max() only keeps a broken driver's 0
  // from turning into inf * 0 = NaN.
  float c_w = clamp((1.0 / max(frag_coord_w, 1e-30)) / foreground_distance_m, 0.0, 1.0);
  float one_minus = 1.0 - c_w;
  return one_minus * one_minus * one_minus * one_minus;
}

// Eq. 1: W = 1 + 8 w_d + 8 w_m, with w_m = min(M / M_max, 1) (Eq. 3).
float fragment_weight(float w_d, float displayed_mip, float mip_max) {
  float w_m = mip_max > 0.0 ? min(displayed_mip / mip_max, 1.0) : 0.0;
  return 1.0 + 8.0 * w_d + 8.0 * w_m;
}
