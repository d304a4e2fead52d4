// Structs and binding numbers read by both C++ (renderer/include/texstream/render/scene/gpu_structs.hpp, which
// static_asserts every size and offset) and GLSL (every shader in this folder). Written once, here (the nvpro
// host_device.h pattern). Only scalar, vec4/uvec4 and mat4 members, so std140 and std430 agree with the plain
// C++ layout; buffers are std430 unless they are the uniform block.
#ifndef TEXSTREAM_SHARED_STRUCTS_H
#define TEXSTREAM_SHARED_STRUCTS_H

#ifdef __cplusplus
#include <cstdint>
namespace texstream::gpu {
using uint = uint32_t;
struct vec4 { float x, y, z, w; };
struct uvec4 { uint32_t x, y, z, w; };
struct mat4 { float m[16]; };  // column-major, as glm and GLSL store it
#define TS_CONST inline constexpr uint32_t
#define TS_FCONST inline constexpr float
#else
#define TS_CONST const uint
#define TS_FCONST const float
#endif

// ---- descriptor set 0: one layout for every pipeline ----
TS_CONST kBindingFrame = 0;        // uniform FrameUniforms
TS_CONST kBindingMeshes = 1;       // buffer MeshGpu[mesh_count], camera-relative offsets, rewritten per frame
TS_CONST kBindingTextures = 2;     // buffer TextureGpu[slots]: by MeshGpu.texture_slot, not by texture id
TS_CONST kBindingMeshMeta = 3;     // buffer MeshMeta[mesh_count], the sparse visibility metadata (seed 000 §3.2)
TS_CONST kBindingCache = 4;        // sampler2DArray[kCachePlanes]: the texture cache images (seed 000 §3.6)
TS_CONST kBindingCompacted = 5;    // buffer CompactList: meshes with weight >= tau (seed 000 §3.3)
TS_CONST kBindingReadback = 6;     // buffer CompactList, host-visible: the used prefix of the compacted list
TS_CONST kBindingLodProbe = 7;     // buffer LodProbeSample[width * height] (LOD_PROBE variant only; else 1 entry)
TS_CONST kBindingProbeSampler = 8; // sampler2DArray: the cache image through a sampler with anisotropy A_m
TS_CONST kBindingOwner = 9;        // usubpassInput: the depth pre-pass's id buffer (mesh id + 1, 0 = none)
TS_CONST kBindingDrawn = 10;       // buffer uint[mesh_count]: the ids of the frame's drawn meshes (compact.comp)
TS_CONST kBindingMetaImage = 11;   // uimage2D (rg32ui): the shading subpass's per-pixel metadata (meta_reduce.comp)
TS_CONST kBindingInstances = 12;   // buffer uint[mesh_count]: the mesh ids of the instanced draws (scene.vert)
// Vertex input: binding 0 holds scene::Vertex (locations 0-2), binding 1 the owning mesh's id per vertex
// (location 3). A draw covers a run of meshes whose indices lie next to each other, so the mesh id comes with
// each vertex, not with the draw (SceneGpu::write_draws).
TS_CONST kVertexMeshLocation = 3u;

// The cache has an image ("plane") per texel format of the scene (rgba8, bc1, bc3, bc7: at most four);
// TextureGpu.placement.x holds the texture's layer and, from kPlacementPlaneShift up, its plane. Bindings of
// planes the scene lacks repeat plane 0 and are never sampled. docs/design/cache_formats.md.
TS_CONST kCachePlanes = 4u;
TS_CONST kPlacementPlaneShift = 24u;
TS_CONST kPlacementLayerMask = 0xffffffu;
// TextureGpu.placement.y when no mip of the texture is resident: the shader draws the colormap colour.
TS_CONST kNotResident = 0xffffffffu;
// MeshMeta.mip_fixed before any fragment wrote it (atomicMin identity).
TS_CONST kNoMip = 0xffffffffu;
// Fixed point of the metadata atomics: mip levels in 1/256 of a level, weights in 1/16 (W <= 17 per fragment,
// so 2^32 / (17 * 16) ~ 15.8 M fragments per mesh before the sum could wrap; a 4K frame has 8.3 M pixels).
TS_CONST kMipFixedScale = 256u;
TS_CONST kWeightFixedScale = 16u;
// The weight sum saturates: a fragment adds only while the sum is below this, so with at most
// (2^32 - 2^31) / (17 * 16) ~ 7.9 M fragments in flight between the read and the add it can never wrap (an 8K
// frame covered by one mesh would otherwise wrap it). Sums at or above it mean "at least this much".
TS_CONST kWeightSaturate = 0x80000000u;
// FrameUniforms.flags.x bits.
TS_CONST kFlagColormapBlend = 1u;  // colormap blending (config stream.colormap_blend)
TS_CONST kFlagLighting = 2u;       // headlight shading; off gives the plain texel colour
TS_CONST kFlagFeedback = 4u;       // write visibility metadata (config render.feedback)
TS_CONST kFlagBlendSeed = 8u;      // blend by Eq. 8 as written (stream.blend = seed), else by the missing levels
TS_CONST kFlagBlendLinear = 16u;   // by the missing fraction (converge_linear), else by its power (converge)
// Bits 8-11 of FrameUniforms.flags.x: stream.blend_exponent (1-8), the power of the missing fraction (converge).
TS_CONST kBlendExponentShift = 8u;
TS_CONST kBlendExponentMask = 15u;
// TextureGpu.colour.w: how the texture is sampled, scene::sampling_flags as written in sampling.bin (the cache
// static_asserts that the two agree): wrap along u and v (kWrap*), alpha test with its cutoff in 1/255.
TS_CONST kSamplingWrapUShift = 0u;
TS_CONST kSamplingWrapVShift = 2u;
TS_CONST kSamplingWrapMask = 3u;
TS_CONST kSamplingAlphaTest = 16u;
TS_CONST kSamplingCutoffShift = 8u;
TS_CONST kWrapClamp = 0u;
TS_CONST kWrapRepeat = 1u;
TS_CONST kWrapMirror = 2u;
TS_CONST kCompactWorkgroupSize = 64u;
// meta_reduce.comp: one invocation per run of kMetaReduceRun pixels of a row, kMetaReduceGroup per workgroup.
TS_CONST kMetaReduceRun = 16u;
TS_CONST kMetaReduceGroup = 64u;
// The shading subpass's metadata attachment (RG32_UINT): x = mesh id + 1 (0: no mesh), y = mip_fixed << 16 |
// weight_fixed. Both fit 16 bits: levels <= 15 (a 32768-texel texture) are <= 3840 in 1/256, and one
// fragment's W <= 17 is <= 272 in 1/16.
TS_CONST kMetaMipShift = 16u;
TS_CONST kMetaWeightMask = 0xffffu;
// FrameUniforms.view.x: what the main pass draws (config render.debug_view). Debug views write raw bytes into a
// UNORM target, so a PNG of them can be decoded exactly.
TS_CONST kDebugViewNone = 0u;
TS_CONST kDebugViewMip = 1u;       // grey = displayed mip level * 16 / 255 (seed 000 Fig. 5 inset): 0 black
TS_CONST kDebugViewWeight = 2u;    // heat map of the per-fragment weight W, 1 (blue) .. 17 (red)
TS_CONST kDebugViewMeshId = 3u;    // RGB = ((mesh id + 1) * kMeshIdHashMul) mod 2^24, 0 = nothing drawn
// The ground's views (issue 28; meshes pure blue): page_level R = (level shown + 1) x 16, G = (level wanted + 1) x 16;
// page_residency green = the wanted page resident, yellow = an ancestor stands in, red = nothing.
TS_CONST kDebugViewPageLevel = 4u;
TS_CONST kDebugViewPageResidency = 5u;
// Odd multiplier (the 24 low bits of the golden-ratio constant 0x9E3779B1): a bijection on 24 bits that
// scatters neighbouring ids over the colour cube; C++ inverts it to decode an id-buffer PNG.
TS_CONST kMeshIdHashMul = 0x3779B1u;

// ---- descriptor set 1: the ground's pages (issue 28; ground.vert, ground.frag, renderer/.../page_cache.hpp) ----
TS_CONST kGroundBindingUniforms = 0u;  // uniform GroundUniforms
TS_CONST kGroundBindingFrames = 1u;    // sampler2DArray: one bordered page per layer (the page cache's frames)
TS_CONST kGroundBindingTable = 2u;     // buffer uint[quadtree slots]: the frame holding each page, kNoPageFrame: none
TS_CONST kGroundBindingNeeds = 3u;     // buffer PageNeedGpu[cols * rows]: the needbuffer (seed 004 §3.2.3)
TS_CONST kNoPageFrame = 0xffffffffu;
// The owner id the ground writes in the depth pre-pass: no mesh has it (mesh id + 1 <= mesh count < 2^32 - 1).
TS_CONST kGroundOwner = 0xffffffffu;

struct GroundUniforms {
  vec4 corner;          // xyz: camera-relative position of the page square's texel (0, 0) corner (metres);
                        // w: metres per texel of the finest level
  uvec4 image;          // x, y: image width and height (finest texels); z: levels; w: page texels (interior)
  uvec4 page;           // x: border texels; y: stored side (border included); z: needbuffer step (px);
                        // w: needbuffer columns
  uvec4 flags;          // x: needbuffer rows; y: 1 = write the needbuffer this frame; z, w: 0
};

// One needbuffer texel: where its pixel meets the ground (page-square units, 0..1), the fractional page level it
// wants (finest = levels - 1) and its eye distance. level is NaN (the buffer is filled with ~0) where no ground
// fragment was shaded.
struct PageNeedGpu {
  float u;
  float v;
  float level;
  float distance;
};

struct FrameUniforms {
  vec4 camera_forward;  // xyz: unit view direction (world axes; the view has no translation)
  vec4 params;          // x: A_m (metadata anisotropy), y: A_s (sampling taps), z: foreground distance (m) of
                        //    Eq. 2, w: ambient term of the headlight
  uvec4 flags;          // x: kFlag* bits, y: mesh count, z: weight cutoff tau in kWeightFixedScale units,
                        // w: capacity of the compacted list (entries)
  uvec4 cache;          // the layer extent (px) of cache planes 0..3 (0: no such plane)
  uvec4 view;           // x: debug view (kDebugView*), y: viewport width (px, row pitch of the LOD probe),
                        // z: meshes drawn this frame (kBindingDrawn; compact.comp's invocations), w: 0
};

// One fragment of the LOD_PROBE variant (tests and texstream-bench visibility): the metadata's level next to
// the level the device's sampler would pick (textureQueryLod with anisotropy A_m) for the same fragment.
struct LodProbeSample {
  float computed;       // anisotropic_lod_of().lod with A_m, unclamped
  float queried;        // textureQueryLod(...).y: the device's lambda for the same footprint
  float mip_max;        // the texture's coarsest level
  float written;        // 1 where a fragment was shaded
};

// Per-pass constants (push constants): the main pass and the wide off-screen metadata pass differ only here.
struct PassConstants {
  mat4 view_proj;       // rotation-only view times projection: vertices arrive camera-relative
  vec4 pass;            // x: lod offset (log2 of this pass's pixel footprint over the viewport's; 0 in the main
                        //    pass), y: weight per fragment (viewport pixels one fragment stands for), zw: |ndc|
                        //    bounds of the viewport inside this pass (> 1 in the main pass: nothing is outside)
};

struct MeshGpu {
  float offset_x;       // mesh origin minus camera position, computed in double on the CPU, then rounded
  float offset_y;
  float offset_z;
  uint texture_id;      // the mesh's texture (compact.comp copies it into CompactEntry for the CPU)
  vec4 rotation;        // unit quaternion (x, y, z, w) turning the vertices (transforms.bin; identity without)
  float scale;          // uniform scale of the vertices before the rotation
  uint texture_slot;    // the texture's entry in the texture table (kBindingTextures; TextureSlots)
  uint reserved0;       // 0
  uint reserved1;       // 0
};

struct TextureGpu {
  uvec4 placement;      // x: cache layer, y: finest resident mip (kNotResident: none), z: coarsest resident mip,
                        // w: mip count of the texture
  uvec4 region;         // x, y: region origin in the layer at mip 0 (px); z, w: texture width, height (px)
  uvec4 colour;         // x: City Colormap RGBA8 (sRGB, R in the low byte), y: the level a fade starts from
                        // (kNotResident: the colormap), z: float bits of the fade left (1 -> 0), w: sampling
                        // flags (kSampling*: wrap modes, alpha test)
};

struct MeshMeta {
  uint mip_fixed;       // atomicMin of the per-fragment mip level (kMipFixedScale units)
  uint weight_fixed;    // atomicAdd of the per-fragment weight W (kWeightFixedScale units)
};

struct CompactEntry {
  uint mesh_id;
  uint mip_fixed;
  uint weight_fixed;
  uint texture_id;      // the mesh's texture (MeshGpu::texture_id): the CPU merges by it without the mesh records
};

#ifdef __cplusplus
// Head of the compacted list buffer (compact.comp declares the same four words, then CompactEntry[]).
struct CompactListHeader {
  uint count;           // atomic counter; may exceed the capacity (entries past it are dropped)
  uint reserved[3];     // 0; keeps the entries 16-byte aligned
};
}  // namespace texstream::gpu
#undef TS_CONST
#undef TS_FCONST
#endif

#endif
