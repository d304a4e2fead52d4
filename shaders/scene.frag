#version 450
// Main pass: shades with the texture cache (only resident mips) and the City Colormap (Eq. 8, stream.blend), and writes the
// fragment's visibility metadata (Eq. 1-3) into a second colour attachment, which meta_reduce.comp sums per
// mesh. It runs in the subpass after the depth pre-pass with an EQUAL depth
// test, so only the fragments that end up in the image run it, and of those only the pixel's owner (the mesh id
// the pre-pass wrote, prepass.frag) goes on: coplanar surfaces both pass EQUAL, yet one pixel has one owner. A
// mesh gets metadata exactly when it owns a pixel, which is what the mesh-id view shows.
// Variants:
//   WIDE_PASS  the small off-screen pass at the wider FOV: metadata only, W = 1 per viewport pixel, for the
//              meshes entirely outside the viewport (seed 000 §3.2; the broad phase sends only those, and a
//              fragment inside the viewport, which only a box's rounding could let through, adds nothing);
//   SUBGROUP_FEEDBACK  (with WIDE_PASS) the wide pass's atomics combined per subgroup first;
//   LOD_PROBE  also writes, per pixel, the metadata's level next to the device's textureQueryLod (tests and
//              texstream-bench visibility check the formula against the hardware).
// FrameUniforms.view.x selects a debug view (render.debug_view): displayed mip as grey, weight heat map,
// mesh ids.
layout(early_fragment_tests) in;  // metadata only from fragments that passed the depth test (seed 000 §3.2)

#ifdef SUBGROUP_FEEDBACK
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#endif

#include "bindings.glsl"
#include "mip_math.glsl"
#include "colour.glsl"

layout(set = 0, binding = kBindingCache) uniform sampler2DArray cache_images[kCachePlanes];
#include "texture_sampling.glsl"

layout(location = 0) in vec2 in_uv;
layout(location = 1) in vec3 in_normal;
layout(location = 2) flat in uint in_mesh;
layout(location = 3) in vec4 in_clip;

#ifndef WIDE_PASS
layout(location = 0) out vec4 out_colour;
// The pixel's mesh and metadata for meta_reduce.comp (layout in shared_structs.h): the main pass writes no buffer.
layout(location = 1) out uvec2 out_meta;
layout(input_attachment_index = 0, set = 0, binding = kBindingOwner) uniform usubpassInput owner_id;
#endif

#ifdef LOD_PROBE
layout(set = 0, binding = kBindingProbeSampler) uniform sampler2DArray probe_image;
layout(set = 0, binding = kBindingLodProbe, std430) writeonly buffer ProbeBlock { LodProbeSample probe[]; };
#endif

// Blue -> cyan -> green -> yellow -> red over t in [0, 1]: the weight heat map.
vec3 heat(float t) {
  t = clamp(t, 0.0, 1.0);
  return clamp(vec3(4.0 * t - 2.0, t < 0.5 ? 2.0 * t * 2.0 : 4.0 - 4.0 * t, 2.0 - 4.0 * t), 0.0, 1.0);
}

// The mesh id view: (id + 1) * kMeshIdHashMul mod 2^24 as three raw bytes (the debug target is UNORM).
vec3 mesh_id_colour(uint mesh) {
  uint code = ((mesh + 1u) * kMeshIdHashMul) & 0xffffffu;
  return vec3(float(code & 0xffu), float((code >> 8) & 0xffu), float(code >> 16)) / 255.0;
}

#ifndef WIDE_PASS
// The texture's colour at sampling level `lod` (resident), N taps along the footprint's major axis, with the
// colormap blend of stream.blend.
vec3 shade_at(TextureGpu tex, AnisoLod s, float lod, vec2 major, vec2 extent, float mip_max, vec3 colormap) {
  // Keep every tap half a texel inside the region at the coarser of the two levels trilinear reads, so
  // filtering never reaches a neighbouring texture in the same layer.
  vec2 level_extent = max(extent / exp2(ceil(lod)), vec2(1.0));
  vec2 lo = 0.5 / level_extent;
  vec2 hi = 1.0 - lo;
  uint plane = texture_plane(tex);
  float inv_layer = 1.0 / float(frame.cache[plane]);
  float layer = float(texture_layer(tex));
  int taps = int(s.taps);
  // A texture that repeats or mirrors (sampling.bin) is filtered here, texel by texel, so that its seams wrap
  // inside the region (texture_sampling.glsl); a clamped one through the sampler, kept inside the region.
  bool wraps = texture_wraps(tex);
  vec4 sum = vec4(0.0);
  for (int i = 0; i < taps; ++i) {
    float t = (float(i) + 0.5) / float(taps) - 0.5;
    if (wraps) {
      sum += sample_wrapped(tex, in_uv + major * t, lod);
    } else {
      vec2 uv = clamp(in_uv + major * t, lo, hi);
      vec2 st = (vec2(tex.region.xy) + uv * extent) * inv_layer;
      sum += cache_lod(plane, vec3(st, layer), lod);
    }
  }
  // Alpha-tested textures are stored with premultiplied colour (BC1 punch-through texels are black): dividing by
  // the filtered alpha keeps the edges of a cut-out from darkening.
  vec3 sampled = texture_alpha_tested(tex) ? sum.rgb / max(sum.a, 1e-4) : sum.rgb / float(taps);
  // Colormap blend c = (1 - M / M_max) c_s + (M / M_max) c_o (seed 000 Eq. 8). stream.blend = seed:
  // M = the displayed level, as written (a far texture stays part colormap for good). converge(_linear): M = the
  // levels still missing, displayed - the level sampled with everything resident, so a texture at its wanted
  // level is drawn exactly as the reference; converge raises M / M_max to the power stream.blend_exponent
  // (docs/design/blend.md).
  float blend = 0.0;
  if ((frame.flags.x & kFlagColormapBlend) != 0u && mip_max > 0.0) {
    bool seed = (frame.flags.x & kFlagBlendSeed) != 0u;
    float m = seed ? lod : max(lod - clamp(s.lod, 0.0, mip_max), 0.0);
    blend = m / mip_max;
    if (!seed && (frame.flags.x & kFlagBlendLinear) == 0u) {
      // An integer power by products: 0 stays exactly 0 (pow(0, n) may go through log2).
      uint n = (frame.flags.x >> kBlendExponentShift) & kBlendExponentMask;
      float fraction = blend;
      for (uint i = 1u; i < n; ++i) blend *= fraction;
    }
  }
  return mix(sampled, colormap, blend);
}
#endif

void main() {
  MeshGpu mesh = meshes[in_mesh];
  TextureGpu tex = textures[mesh.texture_slot];
  vec2 extent = vec2(tex.region.zw);
  // Derivatives first, in uniform control flow.
  vec2 dx = dFdx(in_uv) * extent;
  vec2 dy = dFdy(in_uv) * extent;
  AnisoFootprint footprint = aniso_footprint(dx, dy);  // shared by the sampling level and the metadata's
  float mip_max = float(tex.placement.w - 1u);
  bool resident = tex.placement.y != kNotResident;
  bool feedback = (frame.flags.x & kFlagFeedback) != 0u;
#ifndef WIDE_PASS
  // Not the pixel's owner (a coplanar surface drawn later): neither colour nor metadata. After the derivatives,
  // which need the whole quad.
  if (subpassLoad(owner_id).x != in_mesh + 1u) discard;
#endif

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
    AnisoLod s = anisotropic_lod_of(footprint, frame.params.y);
    float lod = clamp(s.lod, finest, coarsest);
    displayed = lod;
#ifndef WIDE_PASS
    vec2 major = (length(dx) >= length(dy) ? dx : dy) / max(extent, vec2(1.0));
    colour = shade_at(tex, s, lod, major, extent, mip_max, colormap);
    // stream.fade_ms: a level that arrived lately fades in, colour.z (1 -> 0) of the way back to the picture of
    // the finest level before it (colour.y), or to the colormap after a first level (docs/design/blend.md).
    float fade = uintBitsToFloat(tex.colour.z);
    if (fade > 0.0) {
      vec3 before = tex.colour.y == kNotResident
                        ? colormap
                        : shade_at(tex, s, clamp(s.lod, float(tex.colour.y), coarsest), major, extent, mip_max, colormap);
      colour = mix(colour, before, fade);
    }
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
  uint view = frame.view.x;
  if (view == kDebugViewMip) {
    out_colour = vec4(vec3(displayed * 16.0 / 255.0), 1.0);  // grey: byte = 16 x level (seed 000 Fig. 5)
  } else if (view == kDebugViewWeight) {
    out_colour = vec4(heat((weight - 1.0) / 16.0), 1.0);
  } else if (view == kDebugViewMeshId) {
    out_colour = vec4(mesh_id_colour(in_mesh), 1.0);
  } else if (view == kDebugViewPageLevel || view == kDebugViewPageResidency) {
    out_colour = vec4(0.0, 0.0, 1.0, 1.0);  // the ground's views: every mesh pure blue (the ground has no blue)
  } else {
    out_colour = vec4(colour * light, 1.0);
  }
#ifdef LOD_PROBE
  // textureQueryLod's lambda for the same footprint: the region's texels map 1:1 to the layer's, so the
  // layer-space coordinate has the derivatives the metadata used. The probe sampler has anisotropy A_m; its
  // image is plane 0's, so coordinates are in plane 0's layer size whatever the texture's plane.
  vec2 st = (vec2(tex.region.xy) + in_uv * extent) / float(frame.cache.x);
  vec2 queried = textureQueryLod(probe_image, st);
  uint pixel = uint(gl_FragCoord.y) * frame.view.y + uint(gl_FragCoord.x);
  probe[pixel] = LodProbeSample(anisotropic_lod_of(footprint, frame.params.x).lod, queried.y, mip_max, 1.0);
#endif
#endif

  if (!feedback) return;
  // ---- visibility metadata ----
  AnisoLod meta = anisotropic_lod_of(footprint, frame.params.x);
  float wanted = clamp(meta.lod + pc.pass.x, 0.0, mip_max);
  uint mip_fixed = uint(wanted * float(kMipFixedScale));
  uint weight_fixed = uint(weight * float(kWeightFixedScale) + 0.5);
#ifndef WIDE_PASS
  // This fragment owns its pixel (the test above): one value per pixel, reduced per mesh by meta_reduce.comp.
  out_meta = uvec2(in_mesh + 1u, (min(mip_fixed, kMetaWeightMask) << kMetaMipShift) | min(weight_fixed, kMetaWeightMask));
#elif defined(SUBGROUP_FEEDBACK)
  // The wide pass has no owner buffer (several fragments of a pixel may count, as in the seed), so it keeps the
  // atomics, one pair per (subgroup, mesh) instead of per fragment: each pass of the loop takes the mesh of the
  // first remaining lane, reduces min(mip) and sum(W) over the lanes of that mesh, and one of them writes.
  // Helper invocations are not in this branch, so they are not active lanes of the reductions. Integer min and
  // sum do not depend on order: the result equals per-fragment atomics.
  if (!gl_HelperInvocation) {
    bool pending = true;
    while (pending) {
      uint leader = subgroupBroadcastFirst(in_mesh);
      if (in_mesh == leader) {
        uint group_mip = subgroupMin(mip_fixed);
        uint group_weight = subgroupAdd(weight_fixed);  // <= 272 per lane, at most 128 lanes: no overflow
        if (subgroupElect()) {
          if (group_mip < mesh_meta[in_mesh].mip_fixed) atomicMin(mesh_meta[in_mesh].mip_fixed, group_mip);
          if (mesh_meta[in_mesh].weight_fixed < kWeightSaturate)
            atomicAdd(mesh_meta[in_mesh].weight_fixed, group_weight);
        }
        pending = false;
      }
    }
  }
#else
  // Most fragments of a mesh do not lower its minimum: a plain read first skips their atomic (a stale read
  // only lets an unneeded atomicMin through, never skips a needed one, since the value only decreases).
  if (mip_fixed < mesh_meta[in_mesh].mip_fixed) atomicMin(mesh_meta[in_mesh].mip_fixed, mip_fixed);
  // Saturating sum (kWeightSaturate): the plain read may be stale, which only lets a bounded number of
  // in-flight fragments add past the threshold (see shared_structs.h).
  if (mesh_meta[in_mesh].weight_fixed < kWeightSaturate) atomicAdd(mesh_meta[in_mesh].weight_fixed, weight_fixed);
#endif
}
