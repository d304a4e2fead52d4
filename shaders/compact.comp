#version 450
// Metadata compaction (seed 000 §3.3): one invocation per mesh copies meshes with weight >= tau into a dense
// list through an atomic counter, then resets the sparse entry for the next frame.
#include "bindings.glsl"
#include "compact_list.glsl"

layout(local_size_x = kCompactWorkgroupSize) in;

COMPACT_LIST_BLOCK(CompactBlock, kBindingCompacted, ) compacted;

void main() {
  uint mesh = gl_GlobalInvocationID.x;
  if (mesh >= frame.flags.y) return;
  MeshMeta m = mesh_meta[mesh];
  if (m.mip_fixed != kNoMip && m.weight_fixed >= frame.flags.z) {
    uint slot = atomicAdd(compacted.count, 1u);
    if (slot < frame.flags.w) compacted.entries[slot] = CompactEntry(mesh, m.mip_fixed, m.weight_fixed, 0u);
  }
  mesh_meta[mesh] = MeshMeta(kNoMip, 0u);
}
