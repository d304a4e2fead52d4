#version 450
// Depth pre-pass: besides the depth, writes which mesh owns each pixel (mesh id + 1; the clear value 0 means
// "no mesh"). With the GREATER test (reversed Z) a later fragment at exactly the same depth loses, so the owner
// of a pixel is the first-drawn fragment of the nearest depth. scene.frag's shading subpass reads this id and
// lets only the owner shade and write visibility metadata: coplanar surfaces (both pass the EQUAL test) can no
// longer both count as visible. The mesh-id debug view shows the same owners, so it is the exact reference.
layout(early_fragment_tests) in;

layout(location = 2) flat in uint in_mesh;
layout(location = 0) out uint out_owner;

void main() { out_owner = in_mesh + 1u; }
