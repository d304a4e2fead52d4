#version 450
// Read-back, step 2: copy the used prefix of the compacted list into the host-visible read-back buffer
// (dispatched indirectly with compact_args.comp's group count), so the bytes crossing to the host grow with
// the visible meshes, not with the scene (seed 000 §3.3: the full array can be millions of entries).
#include "bindings.glsl"
#include "compact_list.glsl"

layout(local_size_x = kCompactWorkgroupSize) in;

COMPACT_LIST_BLOCK(CompactBlock, kBindingCompacted, readonly) compacted;
COMPACT_LIST_BLOCK(ReadbackBlock, kBindingReadback, writeonly) readback;

void main() {
  uint i = gl_GlobalInvocationID.x;
  uint used = min(compacted.count, frame.flags.w);
  if (i == 0u) readback.count = compacted.count;
  if (i < used) readback.entries[i] = compacted.entries[i];
}
