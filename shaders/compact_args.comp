#version 450
// Read-back, step 1 (only when a streaming cycle starts): turn the compacted list's final count into the
// indirect dispatch of compact_copy.comp, so the copy touches only the used prefix of the list. At least one
// workgroup, so the count itself is always copied.
#include "bindings.glsl"
#include "compact_list.glsl"

layout(local_size_x = 1) in;

COMPACT_LIST_BLOCK(CompactBlock, kBindingCompacted, ) compacted;

void main() {
  uint used = min(compacted.count, frame.flags.w);
  compacted.dispatch_x = max(1u, (used + kCompactWorkgroupSize - 1u) / kCompactWorkgroupSize);
  compacted.dispatch_y = 1u;
  compacted.dispatch_z = 1u;
}
