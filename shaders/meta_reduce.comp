#version 450
// Visibility metadata of the main pass, summed per mesh (seed 000 §3.2 Eq. 1-3). The shading subpass does not
// do the atomics itself: each pixel's owner (the one fragment that shades it) writes its mesh and its
// fragment's level and weight into a colour attachment (scene.frag), and this pass reduces them per mesh: min
// of the levels, sum of the weights. The integers are exactly those per-fragment atomics would have combined
// (min and integer sum do not depend on order), so the compacted list is identical; what changes is the cost.
// A fragment shader with buffer side effects is slow on lavapipe (atomics run lane by lane, fast paths are
// lost) and serialises on a GPU where many fragments hit one mesh's counters; a colour write is cheap, and
// here each invocation walks a run of kMetaReduceRun pixels of one row, which mostly belong to one mesh, and
// writes one atomic pair per change of mesh along the run.
#include "bindings.glsl"

layout(local_size_x = kMetaReduceGroup) in;

layout(set = 0, binding = kBindingMetaImage, rg32ui) uniform readonly uimage2D meta_image;

void flush(uint mesh, uint mip_fixed, uint weight_fixed) {
  if (mesh >= frame.flags.y) return;  // ids come from our own draws; never index past the mesh count
  if (mip_fixed < mesh_meta[mesh].mip_fixed) atomicMin(mesh_meta[mesh].mip_fixed, mip_fixed);
  // Saturating sum (kWeightSaturate): a run adds at most kMetaReduceRun * 272, far inside the margin.
  if (mesh_meta[mesh].weight_fixed < kWeightSaturate) atomicAdd(mesh_meta[mesh].weight_fixed, weight_fixed);
}

void main() {
  ivec2 size = imageSize(meta_image);
  int runs_per_row = (size.x + int(kMetaReduceRun) - 1) / int(kMetaReduceRun);
  int run = int(gl_GlobalInvocationID.x);
  int y = run / runs_per_row;
  if (y >= size.y) return;
  int x0 = (run - y * runs_per_row) * int(kMetaReduceRun);
  int x1 = min(x0 + int(kMetaReduceRun), size.x);
  uint current = 0u;  // mesh id + 1 of the open sum; 0: none
  uint mip_fixed = kNoMip;
  uint weight_fixed = 0u;
  for (int x = x0; x < x1; ++x) {
    uvec2 m = imageLoad(meta_image, ivec2(x, y)).xy;  // x: mesh id + 1 (0: no mesh), y: packed metadata
    if (m.x == 0u) continue;
    if (m.x != current) {
      if (current != 0u) flush(current - 1u, mip_fixed, weight_fixed);
      current = m.x;
      mip_fixed = kNoMip;
      weight_fixed = 0u;
    }
    mip_fixed = min(mip_fixed, m.y >> kMetaMipShift);
    weight_fixed += m.y & kMetaWeightMask;
  }
  if (current != 0u) flush(current - 1u, mip_fixed, weight_fixed);
}
