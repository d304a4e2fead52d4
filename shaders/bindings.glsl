// Descriptor set 0 as every texstream pipeline sees it; the numbers come from shared_structs.h.
#include "shared_structs.h"

layout(set = 0, binding = kBindingFrame, std140) uniform FrameBlock { FrameUniforms frame; };
layout(push_constant, std430) uniform PassBlock { PassConstants pc; };
layout(set = 0, binding = kBindingMeshes, std430) readonly buffer MeshBlock { MeshGpu meshes[]; };
layout(set = 0, binding = kBindingTextures, std430) readonly buffer TextureBlock { TextureGpu textures[]; };
layout(set = 0, binding = kBindingMeshMeta, std430) buffer MeshMetaBlock { MeshMeta mesh_meta[]; };
