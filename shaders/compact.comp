#version 450
// Metadata compaction (seed 000 §3.3): one invocation per drawn mesh of the frame copies it, if its weight is
// >= tau, into a dense list, then resets the mesh's sparse entry for the next frame. Only drawn meshes can have
// metadata (and each mesh is drawn at most once per frame), so visiting the frame's drawn meshes instead of
// every mesh of the scene is exact and costs what the view costs, not what the scene does.
// Variants:
//   (none)           into the device-local list (kBindingCompacted): frames whose list is not read back;
//   COMPACT_TO_HOST  straight into the host-visible read-back list (kBindingReadback): frames that start a
//                    streaming cycle. Only the used prefix is written, so the bytes crossing to the host grow
//                    with the visible meshes, not the scene, without a separate copy dispatch.
// Slots are claimed per workgroup (one atomicAdd on the list counter per 64 meshes, not one per kept mesh):
// cheap on lavapipe, which runs atomics lane by lane, and kind to host memory on a discrete GPU.
#include "bindings.glsl"
#include "compact_list.glsl"

layout(local_size_x = kCompactWorkgroupSize) in;

#ifdef COMPACT_TO_HOST
COMPACT_LIST_BLOCK(CompactBlock, kBindingReadback, ) compacted;
#else
COMPACT_LIST_BLOCK(CompactBlock, kBindingCompacted, ) compacted;
#endif
layout(set = 0, binding = kBindingDrawn, std430) readonly buffer DrawnBlock { uint drawn_mesh[]; };

shared uint group_kept;
shared uint group_base;

void main() {
  if (gl_LocalInvocationIndex == 0u) group_kept = 0u;
  barrier();
  // No early return: the barriers below need every invocation.
  uint k = gl_GlobalInvocationID.x;
  uint mesh = 0u;
  MeshMeta m = MeshMeta(kNoMip, 0u);
  if (k < frame.view.z) {
    mesh = drawn_mesh[k];
    if (mesh < frame.flags.y) {
      m = mesh_meta[mesh];
      mesh_meta[mesh] = MeshMeta(kNoMip, 0u);
    }
  }
  bool keep = m.mip_fixed != kNoMip && m.weight_fixed >= frame.flags.z;
  uint local = keep ? atomicAdd(group_kept, 1u) : 0u;
  barrier();
  if (gl_LocalInvocationIndex == 0u) group_base = group_kept > 0u ? atomicAdd(compacted.count, group_kept) : 0u;
  barrier();
  uint slot = group_base + local;
  // The counter may run past the capacity: entries past it are dropped, the CPU reads min(count, capacity).
  // With the mesh's texture id: the CPU merges the meshes of a texture without reading the mesh records.
  if (keep && slot < frame.flags.w) {
    compacted.entries[slot] = CompactEntry(mesh, m.mip_fixed, m.weight_fixed, meshes[mesh].texture_id);
  }
}
