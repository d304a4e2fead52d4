#version 450
// Main pass: shades with the texture cache (only resident mips) and the City Colormap (Eq. 8), and writes the
// per-mesh visibility metadata (Eq. 1-3). Compiled a second time with WIDE_PASS for the small off-screen pass
// at the wider FOV: that variant writes metadata only, W = 1 per viewport pixel, and only outside the viewport.
layout(early_fragment_tests) in;  // metadata only from fragments that passed the depth test (seed 000 §3.2)

#include "bindings.glsl"
#include "mip_math.glsl"
#include "colour.glsl"

layout(set = 0, binding = kBindingCache) uniform sampler2DArray cache_image;

layout(location = 0) in vec2 in_uv;
layout(location = 1) in vec3 in_normal;
layout(location = 2) flat in uint in_mesh;
layout(location = 3) in vec4 in_clip;

#ifndef WIDE_PASS
layout(location = 0) out vec4 out_colour;
#endif

void main() {
  MeshGpu mesh = meshes[in_mesh];
  TextureGpu tex = textures[mesh.texture_id];
  vec2 extent = vec2(tex.region.zw);
  // Derivatives first, in uniform control flow.
  vec2 dx = dFdx(in_uv) * extent;
  vec2 dy = dFdy(in_uv) * extent;
  float mip_max = float(tex.placement.w - 1u);
  bool resident = tex.placement.y != kNotResident;

  // ---- visibility metadata ----
  AnisoLod meta = anisotropic_lod(dx, dy, frame.params.x);
  float wanted = clamp(meta.lod + pc.pass.x, 0.0, mip_max);
#ifdef WIDE_PASS
  vec2 ndc = in_clip.xy / in_clip.w;
  if (all(lessThanEqual(abs(ndc), pc.pass.zw))) return;  // inside the viewport: the main pass counts it
  float weight = pc.pass.y;  // W = 1 per viewport pixel this fragment stands for (seed 000 §3.2)
#endif

  // ---- shading: sample only mips in [finest, coarsest] resident ----
  vec3 colormap = srgb_to_linear(unpackUnorm4x8(tex.colour.x).rgb);
  vec3 colour = colormap;
  float displayed = mip_max;  // nothing resident: the colormap stands for the coarsest level
  if (resident) {
    float finest = float(tex.placement.y);
    float coarsest = float(tex.placement.z);
    // Sampling anisotropy A_s = A_m / 2, done as N taps of textureLod along the footprint's major axis rather
    // than by the sampler: hardware anisotropy may pick a finer level than our estimate, and without
    // shaderResourceMinLod (lavapipe lacks it) nothing else can clamp it per texture.
    AnisoLod s = anisotropic_lod(dx, dy, frame.params.y);
    float lod = clamp(s.lod, finest, coarsest);
    displayed = lod;
#ifndef WIDE_PASS
    vec2 major = (length(dx) >= length(dy) ? dx : dy) / max(extent, vec2(1.0));
    // Keep every tap half a texel inside the region at the coarser of the two levels trilinear reads, so
    // filtering never reaches a neighbouring texture in the same layer.
    vec2 level_extent = max(extent / exp2(ceil(lod)), vec2(1.0));
    vec2 lo = 0.5 / level_extent;
    vec2 hi = 1.0 - lo;
    float inv_layer = 1.0 / float(frame.cache.x);
    int taps = int(s.taps);
    vec3 sum = vec3(0.0);
    for (int i = 0; i < taps; ++i) {
      float t = (float(i) + 0.5) / float(taps) - 0.5;
      vec2 uv = clamp(in_uv + major * t, lo, hi);
      vec2 st = (vec2(tex.region.xy) + uv * extent) * inv_layer;
      sum += textureLod(cache_image, vec3(st, float(tex.placement.x)), lod).rgb;
    }
    vec3 sampled = sum / float(taps);
    // Eq. 8: c = (1 - M / M_max) c_s + (M / M_max) c_o, M = the displayed level.
    float blend = ((frame.flags.x & kFlagColormapBlend) != 0u && mip_max > 0.0) ? lod / mip_max : 0.0;
    colour = mix(sampled, colormap, blend);
#endif
  }

#ifndef WIDE_PASS
  float weight = fragment_weight(distance_weight(gl_FragCoord.w, frame.params.z), displayed, mip_max);
  // Headlight: exactly 1 where the surface faces the view direction, so a camera-facing quad shows its texels
  // unchanged (the image tests rely on it); two-sided because city meshes are not consistently wound.
  float light = 1.0;
  if ((frame.flags.x & kFlagLighting) != 0u) {
    float facing = abs(dot(normalize(in_normal), frame.camera_forward.xyz));
    light = mix(frame.params.w, 1.0, facing);
  }
  out_colour = vec4(colour * light, 1.0);
#endif

  atomicMin(mesh_meta[in_mesh].mip_fixed, uint(wanted * float(kMipFixedScale)));
  atomicAdd(mesh_meta[in_mesh].weight_fixed, uint(weight * float(kWeightFixedScale) + 0.5));
}
