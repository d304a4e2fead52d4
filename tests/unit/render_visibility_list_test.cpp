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
