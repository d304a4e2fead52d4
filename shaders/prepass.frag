#version 450
// Depth pre-pass: besides the depth, writes which mesh owns each pixel (mesh id + 1; the clear value 0 means
// "no mesh"). With the GREATER test (reversed Z) a later fragment at exactly the same depth loses, so the owner
// of a pixel is the first-drawn fragment of the nearest depth. scene.frag's shading subpass reads this id and
// lets only the owner shade and write visibility metadata: coplanar surfaces (both pass the EQUAL test) can no
// longer both count as visible. The mesh-id view shows the same owners, so it is the exact reference.
// ALPHA_TEST (a scene with cut-out textures, sampling.bin): a fragment of an alpha-tested texture whose alpha at
// the level the main pass would show is below the cutoff is discarded here, so it writes neither depth nor owner
// and the main pass's EQUAL test drops it too; with nothing resident the colormap's alpha decides.
#ifndef ALPHA_TEST
layout(early_fragment_tests) in;
#endif

#ifdef ALPHA_TEST
#include "bindings.glsl"
#include "mip_math.glsl"
layout(set = 0, binding = kBindingCache) uniform sampler2DArray cache_images[kCachePlanes];
#include "texture_sampling.glsl"
layout(location = 0) in vec2 in_uv;
#endif
layout(location = 2) flat in uint in_mesh;
layout(location = 0) out uint out_owner;

void main() {
#ifdef ALPHA_TEST
  TextureGpu tex = textures[meshes[in_mesh].texture_slot];
  vec2 extent = vec2(tex.region.zw);
  vec2 dx = dFdx(in_uv) * extent;  // in uniform control flow
  vec2 dy = dFdy(in_uv) * extent;
  if (texture_alpha_tested(tex)) {
    float alpha = unpackUnorm4x8(tex.colour.x).a;
    if (tex.placement.y != kNotResident) {
      float lod = anisotropic_lod_of(aniso_footprint(dx, dy), frame.params.y).lod;
      alpha = sample_wrapped(tex, in_uv, clamp(lod, float(tex.placement.y), float(tex.placement.z))).a;
    }
    if (alpha < texture_alpha_cutoff(tex)) discard;
  }
#endif
  out_owner = in_mesh + 1u;
}
