// From the compacted per-mesh metadata to the sorted per-texture candidate list.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>

#include "texstream/render/frame/visibility_list.hpp"

using namespace texstream;
using namespace texstream::render;

TEST(VisibilityList, MergesMeshesOfOneTextureAndSortsByWeight) {
  std::vector<scene::MeshRecord> meshes(4);
  meshes[0].texture_id = 7;
  meshes[1].texture_id = 3;
  meshes[2].texture_id = 7;  // shares texture 7 with mesh 0
  meshes[3].texture_id = 1;
  // compact.comp writes each mesh's texture id into its entry.
  const std::vector<gpu::CompactEntry> entries{
      {0, 3 * gpu::kMipFixedScale, 100 * gpu::kWeightFixedScale, 7},
      {1, 2 * gpu::kMipFixedScale + gpu::kMipFixedScale / 2, 500 * gpu::kWeightFixedScale, 3},
      {2, 1 * gpu::kMipFixedScale, 450 * gpu::kWeightFixedScale, 7},
      {3, 0, 8, 1},      // weight 0.5
      {99, 0, 1000, 1},  // bad mesh id from the GPU: skipped
      {3, 0, 1000, 8},   // bad texture id from the GPU (the scene has 8 textures): skipped
  };
  uint64_t skipped = 0;
  const auto c = build_candidates(entries, meshes.size(), 8, &skipped);
  EXPECT_EQ(skipped, 2u);
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
  for (uint32_t i = 0; i < 3; ++i) meshes[i].texture_id = 0;  // texture 0: one big and two tiny meshes
  for (uint32_t i = 3; i < 6; ++i) meshes[i].texture_id = 1;  // texture 1: the same sum in one mesh
  const uint32_t one = gpu::kWeightFixedScale;                // weight 1.0 in fixed point
  const uint32_t big = (1u << 24) * one;                      // weight 2^24
  const std::vector<gpu::CompactEntry> entries{
      {0, 0, big, 0},
      {1, 0, one, 0},
      {2, 0, one, 0},
      {3, 0, big + 2 * one, 1},
  };
  const auto first = build_candidates(entries, meshes.size(), 2);
  const std::vector<gpu::CompactEntry> reversed(entries.rbegin(), entries.rend());
  const auto second = build_candidates(reversed, meshes.size(), 2);
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

// The list against a model built the plain way (a map per texture, then std::sort with the documented order:
// weight descending, ties by texture id), on random lists with shared textures, equal weights and bad ids; short
// lists take the radix sort, long ones (>= 2^15) TBB's parallel sort: both must give the model's order.
TEST(VisibilityList, AgreesWithAPlainModelOnRandomLists) {
  std::mt19937 rng(5);
  for (const size_t n : {size_t{0}, size_t{1}, size_t{2}, size_t{300}, size_t{5000}, size_t{40000}}) {
    for (const uint32_t textures : {3u, 1000u, 3000000u}) {
      std::vector<scene::MeshRecord> meshes(std::max<size_t>(n, 1));
      for (auto& m : meshes) m.texture_id = static_cast<uint32_t>(rng() % textures);
      std::vector<gpu::CompactEntry> entries(n);
      for (auto& e : entries) {
        const uint32_t mesh = rng() % 50 == 0 ? static_cast<uint32_t>(meshes.size() + rng() % 9)  // bad id
                                              : static_cast<uint32_t>(rng() % meshes.size());
        // Few distinct weights, so that equal sums (ties) are common.
        const uint32_t texture = mesh < meshes.size() ? meshes[mesh].texture_id : 0;
        e = {mesh, static_cast<uint32_t>(rng() % (12 * gpu::kMipFixedScale)),
             static_cast<uint32_t>((rng() % 8) * gpu::kWeightFixedScale + (rng() % 3)),
             rng() % 50 == 0 ? textures + static_cast<uint32_t>(rng() % 9) : texture};  // or a bad texture id
      }
      std::map<uint32_t, std::pair<uint32_t, uint64_t>> model_sums;  // texture -> (min mip, weight sum)
      uint64_t model_bad = 0;
      for (const auto& e : entries) {
        if (e.mesh_id >= meshes.size() || e.texture_id >= textures || e.mip_fixed == gpu::kNoMip) {
          ++model_bad;
          continue;
        }
        auto [it, fresh] = model_sums.try_emplace(e.texture_id, e.mip_fixed, 0);
        it->second.first = std::min(it->second.first, e.mip_fixed);
        it->second.second += e.weight_fixed;
      }
      std::vector<stream::StreamCandidate> model;
      for (const auto& [t, v] : model_sums) {
        model.push_back({TextureId(t), static_cast<float>(v.first) / static_cast<float>(gpu::kMipFixedScale),
                         static_cast<float>(static_cast<double>(v.second) / gpu::kWeightFixedScale)});
      }
      std::sort(model.begin(), model.end(), [](const stream::StreamCandidate& a, const stream::StreamCandidate& b) {
        return a.weight != b.weight ? a.weight > b.weight : a.texture < b.texture;
      });
      uint64_t bad = 0;
      const auto got = build_candidates(entries, meshes.size(), textures, &bad);
      EXPECT_EQ(bad, model_bad);
      ASSERT_EQ(got.size(), model.size()) << "n " << n << ", textures " << textures;
      for (size_t i = 0; i < got.size(); ++i) {
        ASSERT_EQ(got[i].texture, model[i].texture) << "n " << n << ", textures " << textures << ", position " << i;
        ASSERT_EQ(got[i].weight, model[i].weight) << "position " << i;
        ASSERT_EQ(got[i].desired_mip, model[i].desired_mip) << "position " << i;
      }
    }
  }
}
