// From the compacted per-mesh metadata to the sorted per-texture candidate list.
#include <gtest/gtest.h>

#include "texstream/render/visibility_list.hpp"

using namespace texstream;
using namespace texstream::render;

TEST(VisibilityList, MergesMeshesOfOneTextureAndSortsByWeight) {
  std::vector<scene::MeshRecord> meshes(4);
  meshes[0].texture_id = 7;
  meshes[1].texture_id = 3;
  meshes[2].texture_id = 7;  // shares texture 7 with mesh 0
  meshes[3].texture_id = 1;
  const std::vector<gpu::CompactEntry> entries{
      {0, 3 * gpu::kMipFixedScale, 100 * gpu::kWeightFixedScale, 0},
      {1, 2 * gpu::kMipFixedScale + gpu::kMipFixedScale / 2, 500 * gpu::kWeightFixedScale, 0},
      {2, 1 * gpu::kMipFixedScale, 450 * gpu::kWeightFixedScale, 0},
      {3, 0, 8, 0},      // weight 0.5
      {99, 0, 1000, 0},  // bad mesh id from the GPU: skipped
  };
  uint64_t skipped = 0;
  const auto c = build_candidates(entries, meshes, &skipped);
  EXPECT_EQ(skipped, 1u);
  ASSERT_EQ(c.size(), 3u);
  EXPECT_EQ(c[0].texture, TextureId(7));  // 100 + 450
  EXPECT_FLOAT_EQ(c[0].weight, 550.0f);
  EXPECT_FLOAT_EQ(c[0].desired_mip, 1.0f);  // the finer of 3 and 1
  EXPECT_EQ(c[1].texture, TextureId(3));
  EXPECT_FLOAT_EQ(c[1].desired_mip, 2.5f);
  EXPECT_EQ(c[2].texture, TextureId(1));
  EXPECT_FLOAT_EQ(c[2].weight, 0.5f);
}

// The compaction's atomics write entries in any order; the merged list must not depend on it. Weights chosen so
// that float sums round differently by order: (2^24 + 1) + 1 = 2^24 but (1 + 1) + 2^24 = 2^24 + 2 in float;
// the fixed-point sum is exact either way, and ties with texture 1's single 2^24 + 2.
TEST(VisibilityList, MergedWeightsDoNotDependOnEntryOrder) {
  std::vector<scene::MeshRecord> meshes(6);
  for (uint32_t i = 0; i < 3; ++i) meshes[i].texture_id = 0;      // texture 0: one big and two tiny meshes
  for (uint32_t i = 3; i < 6; ++i) meshes[i].texture_id = 1;      // texture 1: the same sum in one mesh
  const uint32_t one = gpu::kWeightFixedScale;  // weight 1.0 in fixed point
  const uint32_t big = (1u << 24) * one;         // weight 2^24
  const std::vector<gpu::CompactEntry> entries{
      {0, 0, big, 0}, {1, 0, one, 0}, {2, 0, one, 0}, {3, 0, big + 2 * one, 0},
  };
  const auto first = build_candidates(entries, meshes);
  const std::vector<gpu::CompactEntry> reversed(entries.rbegin(), entries.rend());
  const auto second = build_candidates(reversed, meshes);
  ASSERT_EQ(first.size(), 2u);
  ASSERT_EQ(second.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(first[i].texture, second[i].texture);
    EXPECT_EQ(first[i].weight, second[i].weight);
  }
  // Equal sums: the tie goes to the lower texture id, whatever the order.
  EXPECT_EQ(first[0].texture, TextureId(0));
  EXPECT_FLOAT_EQ(first[0].weight, 16777218.0f);
}
