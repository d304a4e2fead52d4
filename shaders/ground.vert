#version 450
// The ground (issue 28): one quad over the image of the scene's huge ground texture (scene.json "ground"),
// camera-relative like every mesh (the corner is computed in double on the CPU). Its fragments get the texel
// position at the finest level, from which ground.frag derives the level each pixel wants.
#include "bindings.glsl"

layout(set = 1, binding = kGroundBindingUniforms, std140) uniform GroundBlock { GroundUniforms ground; };

// The pre-pass and the shading subpass run this shader in two pipelines: bit-identical depths (EQUAL test).
invariant gl_Position;

layout(location = 0) out vec2 out_tex;  // texels of the finest level, u east, v north
layout(location = 1) out vec3 out_rel;  // camera-relative position (metres)

void main() {
  // Two triangles: corners (0,0) (1,0) (0,1) and (1,0) (1,1) (0,1).
  const vec2 corners[6] = vec2[6](vec2(0, 0), vec2(1, 0), vec2(0, 1), vec2(1, 0), vec2(1, 1), vec2(0, 1));
  vec2 c = corners[gl_VertexIndex];
  vec2 texels = c * vec2(ground.image.xy);
  vec3 rel = ground.corner.xyz + vec3(texels * ground.corner.w, 0.0);
  gl_Position = pc.view_proj * vec4(rel, 1.0);
  out_tex = texels;
  out_rel = rel;
}
