#version 450
// The ground's huge texture through its pages (issue 28; seed 004 §3.2, seed 002 §4): each pixel wants the level
// its footprint asks for, samples that page or, while it is missing, its nearest resident ancestor (the frame
// table walked upwards), bilinear inside the bordered page and trilinear between two levels, as an ordinary
// mipmapped texture would be sampled (texstream-bench pages' CPU sampler does the same; docs/design/pages.md).
// Every step-th pixel per axis also writes what it wants into the needbuffer, read back by the page policy.
// PREPASS: the depth pre-pass's variant, which only claims the pixel for the ground (kGroundOwner).
// GROUND_REFERENCE: the same texture as one ordinary mipmapped image (pages.reference), trilinear by the device at
// the same level: the reference the pages are compared with (seams).
layout(early_fragment_tests) in;

#include "bindings.glsl"
#include "colour.glsl"

layout(set = 1, binding = kGroundBindingUniforms, std140) uniform GroundBlock { GroundUniforms ground; };

#ifdef PREPASS
// The vertex stage's outputs, declared so the interface matches (unused here).
layout(location = 0) in vec2 in_tex;
layout(location = 1) in vec3 in_rel;
layout(location = 0) out uint out_owner;
void main() { out_owner = kGroundOwner; }
#else
layout(set = 1, binding = kGroundBindingFrames) uniform sampler2DArray frames;
layout(set = 1, binding = kGroundBindingTable, std430) readonly buffer TableBlock { uint frame_of_slot[]; };
layout(set = 1, binding = kGroundBindingNeeds, std430) writeonly buffer NeedBlock { PageNeedGpu needs[]; };
layout(input_attachment_index = 0, set = 0, binding = kBindingOwner) uniform usubpassInput owner_id;

layout(location = 0) in vec2 in_tex;
layout(location = 1) in vec3 in_rel;
layout(location = 0) out vec4 out_colour;
layout(location = 1) out uvec2 out_meta;

// Absolute quadtree slot of page (x, y) of `level` (page_file.hpp: (4^l - 1) / 3 + y * 2^l + x).
uint slot_of(uint level, uvec2 p) { return ((1u << (2u * level)) - 1u) / 3u + p.y * (1u << level) + p.x; }

uvec2 page_at(uint level, vec2 uv) {
  float n = float(1u << level);
  return uvec2(clamp(floor(uv * n), vec2(0.0), vec2(n - 1.0)));
}

// Bilinear colour of `level` at uv from the page holding uv or its nearest resident ancestor; `shown` is the
// level sampled (kNoPageFrame: nothing resident above, the colour is the background).
vec4 sample_level(uint level, vec2 uv, out uint shown) {
  for (int l = int(level); l >= 0; --l) {
    uvec2 p = page_at(uint(l), uv);
    uint f = frame_of_slot[slot_of(uint(l), p)];
    if (f == kNoPageFrame) continue;
    float extent = float(ground.image.w << uint(l));
    vec2 local = (uv * extent - vec2(p) * float(ground.image.w) + float(ground.page.x)) / float(ground.page.y);
    shown = uint(l);
    return textureLod(frames, vec3(local, float(f)), 0.0);
  }
  shown = kNoPageFrame;
  return vec4(srgb_to_linear(vec3(0.25, 0.375, 0.5)), 1.0);  // texstream-bench pages' kGroundBackground
}

void main() {
  // Texels of the finest level per pixel: the longer footprint edge (the CPU sampler's rho), taken while every
  // invocation of the quad is still running.
  float rho = max(length(dFdx(in_tex)), length(dFdy(in_tex)));
  if (subpassLoad(owner_id).x != kGroundOwner) discard;
  uint levels = ground.image.z;
  float virtual_side = float(ground.image.w << (levels - 1u));
  vec2 uv = in_tex / virtual_side;
  float level = clamp(float(levels - 1u) - log2(max(rho, 1e-9)), 0.0, float(levels - 1u));
  uint coarse = uint(floor(level));
  float t = level - float(coarse);
  uint wanted = t >= 0.5 && coarse + 1u < levels ? coarse + 1u : coarse;
#ifdef GROUND_REFERENCE
  uint shown = wanted;
  vec4 c = textureLod(frames, vec3(uv, 0.0), float(levels - 1u) - level);
#else
  uint shown = kNoPageFrame;
  vec4 c = sample_level(coarse, uv, shown);
  if (t > 0.0 && coarse + 1u < levels) {
    uint shown_fine = kNoPageFrame;
    c = mix(c, sample_level(coarse + 1u, uv, shown_fine), t);
    if (t >= 0.5) shown = shown_fine;
  }
#endif

  // Headlight as on every mesh (scene.frag): the ground's normal is +z.
  float light = 1.0;
  if ((frame.flags.x & kFlagLighting) != 0u) light = mix(frame.params.w, 1.0, abs(frame.camera_forward.z));
  uint view = frame.view.x;
  if (view == kDebugViewPageLevel) {
    float s = shown == kNoPageFrame ? 0.0 : float(shown + 1u) * 16.0 / 255.0;
    out_colour = vec4(s, float(wanted + 1u) * 16.0 / 255.0, 0.0, 1.0);
  } else if (view == kDebugViewPageResidency) {
    out_colour = shown == kNoPageFrame ? vec4(1, 0, 0, 1) : shown >= wanted ? vec4(0, 1, 0, 1) : vec4(1, 1, 0, 1);
  } else if (view == kDebugViewMeshId) {
    out_colour = vec4(0.0, 0.0, 0.0, 1.0);  // not a mesh
  } else {
    out_colour = vec4(c.rgb * light, 1.0);
  }
  out_meta = uvec2(0u);  // no mesh: meta_reduce skips the pixel

  if (ground.flags.y == 0u) return;
  uvec2 px = uvec2(gl_FragCoord.xy);
  uint stride = ground.page.z;
  if (px.x % stride != 0u || px.y % stride != 0u) return;
  uvec2 cell = px / stride;
  if (cell.x < ground.page.w && cell.y < ground.flags.x)
    needs[cell.y * ground.page.w + cell.x] = PageNeedGpu(uv.x, uv.y, level, length(in_rel));
}
#endif
