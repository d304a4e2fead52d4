#pragma once
// C++ view of shaders/shared_structs.h with every size and offset pinned: a field moved on one side only
// breaks the build, not the picture.
#include <cstddef>
#include <type_traits>

#include "shared_structs.h"

namespace texstream::gpu {

static_assert(sizeof(vec4) == 16 && sizeof(uvec4) == 16 && sizeof(mat4) == 64);

static_assert(sizeof(GroundUniforms) == 64 && offsetof(GroundUniforms, flags) == 48);
static_assert(sizeof(PageNeedGpu) == 16 && offsetof(PageNeedGpu, distance) == 12);
static_assert(sizeof(FrameUniforms) == 80);
static_assert(offsetof(FrameUniforms, camera_forward) == 0);
static_assert(offsetof(FrameUniforms, params) == 16);
static_assert(offsetof(FrameUniforms, flags) == 32);
static_assert(offsetof(FrameUniforms, cache) == 48);
static_assert(offsetof(FrameUniforms, view) == 64);
static_assert(sizeof(LodProbeSample) == 16);

static_assert(sizeof(PassConstants) == 80);  // push constants: Vulkan guarantees 128 bytes
static_assert(offsetof(PassConstants, view_proj) == 0);
static_assert(offsetof(PassConstants, pass) == 64);

static_assert(sizeof(MeshGpu) == 48);  // std430: three floats, a uint, a vec4, a float, three uints, no padding
static_assert(offsetof(MeshGpu, offset_x) == 0);
static_assert(offsetof(MeshGpu, offset_z) == 8);
static_assert(offsetof(MeshGpu, texture_id) == 12);
static_assert(offsetof(MeshGpu, rotation) == 16);
static_assert(offsetof(MeshGpu, scale) == 32);
static_assert(offsetof(MeshGpu, texture_slot) == 36);
static_assert(offsetof(MeshGpu, reserved1) == 44);

static_assert(sizeof(TextureGpu) == 48);
static_assert(offsetof(TextureGpu, placement) == 0);
static_assert(offsetof(TextureGpu, region) == 16);
static_assert(offsetof(TextureGpu, colour) == 32);

static_assert(sizeof(MeshMeta) == 8);
static_assert(offsetof(MeshMeta, weight_fixed) == 4);

static_assert(sizeof(CompactEntry) == 16);
static_assert(offsetof(CompactEntry, mip_fixed) == 4);
static_assert(offsetof(CompactEntry, weight_fixed) == 8);
static_assert(offsetof(CompactEntry, texture_id) == 12);
static_assert(sizeof(CompactListHeader) == 16);  // compact.comp: four uints, then the entries
static_assert(offsetof(CompactListHeader, reserved) == 4);

static_assert(std::is_trivially_copyable_v<TextureGpu> && std::is_trivially_copyable_v<MeshGpu>);

}  // namespace texstream::gpu
