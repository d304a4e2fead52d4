#version 450
// Scene vertices: positions relative to their mesh origin, moved by the mesh's camera-relative offset
// (computed in double on the CPU), so the view matrix has no translation and nothing jitters at map
// coordinates. Each vertex carries its mesh's id (one indirect draw covers a run of meshes, SceneGpu::write_draws);
// the instances of one shared range are one instanced draw, each instance's mesh id in the instances buffer.
#include "bindings.glsl"

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;
layout(location = 2) in vec2 in_uv;
layout(location = kVertexMeshLocation) in uint in_mesh;
layout(set = 0, binding = kBindingInstances, std430) readonly buffer InstanceBlock { uint instance_mesh[]; };

// The depth pre-pass and the main pass run this same shader in two pipelines; invariance makes their depths
// bit-identical, so the main pass's EQUAL depth test keeps exactly the fragments that ended up visible.
invariant gl_Position;

layout(location = 0) out vec2 out_uv;
layout(location = 1) out vec3 out_normal;
layout(location = 2) flat out uint out_mesh;
layout(location = 3) out vec4 out_clip;

// v turned by the unit quaternion q (x, y, z, w).
vec3 rotate(vec4 q, vec3 v) { return v + 2.0 * cross(q.xyz, cross(q.xyz, v) + q.w * v); }

void main() {
  // Instanced draws start at firstInstance = 1 + their run's place in the instances buffer (their vertices carry
  // the owner's id); runs of meshes draw at instance 0, their vertices carrying their own ids.
  uint id = gl_InstanceIndex > 0 ? instance_mesh[uint(gl_InstanceIndex) - 1u] : in_mesh;
  MeshGpu mesh = meshes[id];
  // transforms.bin: the instance's rotation and uniform scale, then its camera-relative origin.
  vec3 relative = rotate(mesh.rotation, in_position * mesh.scale) + vec3(mesh.offset_x, mesh.offset_y, mesh.offset_z);
  gl_Position = pc.view_proj * vec4(relative, 1.0);
  out_uv = in_uv;
  out_normal = rotate(mesh.rotation, in_normal);
  out_mesh = id;
  out_clip = gl_Position;
}
