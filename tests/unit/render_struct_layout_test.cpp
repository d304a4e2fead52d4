// The structs shared with GLSL (shaders/shared_structs.h) keep the std430/std140 layout the shaders assume.
// gpu_structs.hpp pins them at compile time; this test pins them again and checks the values the shaders
// depend on.
#include <gtest/gtest.h>

#include <cstddef>

#include "texstream/render/scene/gpu_structs.hpp"

using namespace texstream::gpu;

TEST(SharedStructs, SizesAndOffsets) {
  EXPECT_EQ(sizeof(TextureGpu), 48u);
  EXPECT_EQ(offsetof(TextureGpu, placement), 0u);
  EXPECT_EQ(offsetof(TextureGpu, region), 16u);
  EXPECT_EQ(offsetof(TextureGpu, colour), 32u);
  EXPECT_EQ(sizeof(MeshGpu), 48u);
  EXPECT_EQ(offsetof(MeshGpu, texture_id), 12u);
  EXPECT_EQ(offsetof(MeshGpu, rotation), 16u);
  EXPECT_EQ(offsetof(MeshGpu, scale), 32u);
  EXPECT_EQ(offsetof(MeshGpu, texture_slot), 36u);
  EXPECT_EQ(offsetof(MeshGpu, reserved1), 44u);
  EXPECT_EQ(sizeof(MeshMeta), 8u);
  EXPECT_EQ(sizeof(CompactEntry), 16u);
  EXPECT_EQ(sizeof(CompactListHeader), 16u);
  EXPECT_EQ(sizeof(FrameUniforms), 80u);
  EXPECT_EQ(offsetof(FrameUniforms, view), 64u);
  EXPECT_EQ(sizeof(LodProbeSample), 16u);
  EXPECT_EQ(offsetof(CompactListHeader, reserved), 4u);
  EXPECT_EQ(sizeof(PassConstants), 80u);
  EXPECT_LE(sizeof(PassConstants), 128u);  // Vulkan's guaranteed push-constant size
}

TEST(SharedStructs, FixedPointHasHeadroom) {
  // W <= 17 per fragment (Eq. 1 with w_d = w_m = 1): a 4K frame of one mesh must not wrap the sum.
  const double max_per_fragment = 17.0 * kWeightFixedScale;
  EXPECT_GT(4294967295.0 / max_per_fragment, 3840.0 * 2160.0);
  // Mip levels up to 15 (kMaxTextureExtent = 2^15) in 1/256 steps stay far below the "no mip" marker.
  EXPECT_LT(15u * kMipFixedScale, kNoMip);
  EXPECT_NE(kNotResident, 0u);
}

TEST(SharedStructs, SaturatedWeightCannotWrap) {
  // Between the read of the sum and the add, every fragment in flight may add 17 * kWeightFixedScale: the
  // headroom above kWeightSaturate must hold millions of them (more than any GPU keeps in flight).
  const double headroom = 4294967296.0 - static_cast<double>(kWeightSaturate);
  EXPECT_GT(headroom / (17.0 * kWeightFixedScale), 7.0e6);
  // Still above what a ranking needs: a 1440p frame covered by one mesh of W = 17 fragments stays exact.
  EXPECT_GT(static_cast<double>(kWeightSaturate), 2560.0 * 1440.0 * 17.0 * kWeightFixedScale);
}

TEST(SharedStructs, MeshIdHashIsABijectionOn24Bits) {
  EXPECT_EQ(kMeshIdHashMul % 2u, 1u);  // odd: invertible modulo 2^24
  EXPECT_LT(kMeshIdHashMul, 1u << 24);
}
