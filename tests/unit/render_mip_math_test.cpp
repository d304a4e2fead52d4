// The CPU twin of the shader's mip-level and weight formulas (seed 000 §3.2, Eq. 1-3; Hollemeersch et al.)
// against values worked out by hand.
#include <gtest/gtest.h>

#include <cmath>

#include "texstream/render/frame/mip_math.hpp"

using namespace texstream::render;

TEST(MipMath, IsotropicFootprintGivesLog2OfTexelsPerPixel) {
  // 4 texels per pixel along both axes: lod 2, one tap.
  auto r = anisotropic_lod(4, 0, 0, 4, 16);
  EXPECT_FLOAT_EQ(r.lod, 2.0f);
  EXPECT_FLOAT_EQ(r.taps, 1.0f);
  // One texel per pixel, rotated 45 degrees: still lod 0.
  const float s = std::sqrt(0.5f);
  auto q = anisotropic_lod(s, s, -s, s, 16);
  EXPECT_NEAR(q.lod, 0.0f, 1e-6f);
}

TEST(MipMath, AnisotropyDividesTheMajorAxis) {
  // 8:1 footprint (8 texels along x, 1 along y): N = 8, lod = log2(8 / 8) = 0.
  auto r = anisotropic_lod(8, 0, 0, 1, 16);
  EXPECT_FLOAT_EQ(r.taps, 8.0f);
  EXPECT_FLOAT_EQ(r.lod, 0.0f);
  // 32:1 with A_m = 16: N is clamped to 16, lod = log2(32 / 16) = 1.
  auto c = anisotropic_lod(0, 32, 1, 0, 16);
  EXPECT_FLOAT_EQ(c.taps, 16.0f);
  EXPECT_FLOAT_EQ(c.lod, 1.0f);
  // 3:1.5 -> ratio 2: N = 2, lod = log2(1.5).
  auto h = anisotropic_lod(3, 0, 0, 1.5f, 16);
  EXPECT_FLOAT_EQ(h.taps, 2.0f);
  EXPECT_FLOAT_EQ(h.lod, std::log2(1.5f));
  // Ratio 2.5 rounds N up to 3: lod = log2(5 / 3).
  auto u = anisotropic_lod(5, 0, 0, 2, 16);
  EXPECT_FLOAT_EQ(u.taps, 3.0f);
  EXPECT_NEAR(u.lod, std::log2(5.0f / 3.0f), 1e-6f);
  // Sampling anisotropy A_s = A_m / 2 = 8 on the same 32:1 footprint: lod log2(32 / 8) = 2.
  EXPECT_FLOAT_EQ(anisotropic_lod(32, 0, 0, 1, 8).lod, 2.0f);
}

TEST(MipMath, DegenerateFootprints) {
  auto flat = anisotropic_lod(6, 0, 0, 0, 16);  // p_min = 0: maximal anisotropy
  EXPECT_FLOAT_EQ(flat.taps, 16.0f);
  EXPECT_FLOAT_EQ(flat.lod, std::log2(6.0f / 16.0f));
  auto none = anisotropic_lod(0, 0, 0, 0, 16);  // no change across the pixel: clamped by the caller
  EXPECT_LT(none.lod, -30.0f);
}

TEST(MipMath, DistanceWeightEq2) {
  // c_w = min(w / D, 1), w_d = (1 - c_w)^4.
  EXPECT_FLOAT_EQ(distance_weight(0.0f, 500.0f), 1.0f);
  EXPECT_FLOAT_EQ(distance_weight(250.0f, 500.0f), 0.0625f);
  EXPECT_FLOAT_EQ(distance_weight(500.0f, 500.0f), 0.0f);
  EXPECT_FLOAT_EQ(distance_weight(5000.0f, 500.0f), 0.0f);
}

TEST(MipMath, FragmentWeightEq1And3) {
  EXPECT_FLOAT_EQ(fragment_weight(0.0f, 0.0f, 8.0f), 1.0f);   // far away, finest mip shown
  EXPECT_FLOAT_EQ(fragment_weight(1.0f, 8.0f, 8.0f), 17.0f);  // at the camera, coarsest shown
  EXPECT_FLOAT_EQ(fragment_weight(0.5f, 2.0f, 8.0f), 1.0f + 4.0f + 2.0f);
  EXPECT_FLOAT_EQ(fragment_weight(0.0f, 3.0f, 0.0f), 1.0f);  // a 1x1 texture has no coarser level
}
