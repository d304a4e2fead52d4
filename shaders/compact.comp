#version 450
// Metadata compaction (seed 000 §3.3): one invocation per mesh copies meshes with weight >= tau into a dense
// list through an atomic counter, then resets the sparse entry for the next frame.
#include "bindings.glsl"

layout(local_size_x = kCompactWorkgroupSize) in;

layout(set = 0, binding = kBindingCompacted, std430) buffer CompactBlock {
  uint compact_count;  // may run past capacity: entries past it are dropped, the CPU reads min(count, capacity)
  uint compact_reserved0;
  uint compact_reserved1;
  uint compact_reserved2;
  CompactEntry compact_entries[];
};

void main() {
  uint mesh = gl_GlobalInvocationID.x;
  if (mesh >= frame.flags.y) return;
  MeshMeta m = mesh_meta[mesh];
  if (m.mip_fixed != kNoMip && m.weight_fixed >= frame.flags.z) {
    uint slot = atomicAdd(compact_count, 1u);
    if (slot < frame.flags.w) compact_entries[slot] = CompactEntry(mesh, m.mip_fixed, m.weight_fixed, 0u);
  }
  mesh_meta[mesh] = MeshMeta(kNoMip, 0u);
}
