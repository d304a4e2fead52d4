#include "texstream/render/visibility_list.hpp"

#include <tbb/parallel_sort.h>

#include <algorithm>
#include <unordered_map>

namespace texstream::render {

std::vector<StreamCandidate> build_candidates(std::span<const gpu::CompactEntry> entries,
                                              std::span<const scene::MeshRecord> meshes, uint64_t* skipped) {
  std::unordered_map<uint32_t, size_t> index;  // texture id -> position in out
  std::vector<StreamCandidate> out;
  out.reserve(entries.size());
  // Weights summed in the GPU's fixed point (exact, so the sum, and with it the order, does not depend on the
  // order the compaction's atomics wrote the entries in), converted once at the end.
  std::vector<uint64_t> weight_fixed;
  weight_fixed.reserve(entries.size());
  uint64_t bad = 0;
  for (const gpu::CompactEntry& e : entries) {
    if (e.mesh_id >= meshes.size() || e.mip_fixed == gpu::kNoMip) {
      ++bad;
      continue;
    }
    const uint32_t texture = meshes[e.mesh_id].texture_id;
    const float mip = static_cast<float>(e.mip_fixed) / static_cast<float>(gpu::kMipFixedScale);
    auto [it, inserted] = index.emplace(texture, out.size());
    if (inserted) {
      out.push_back(StreamCandidate{TextureId(texture), mip, 0.0f});
      weight_fixed.push_back(e.weight_fixed);
    } else {
      StreamCandidate& c = out[it->second];
      c.desired_mip = std::min(c.desired_mip, mip);
      weight_fixed[it->second] += e.weight_fixed;
    }
  }
  for (size_t i = 0; i < out.size(); ++i)
    out[i].weight = static_cast<float>(static_cast<double>(weight_fixed[i]) / gpu::kWeightFixedScale);
  // Parallel CPU sort as in seed 000 §3.3 (TBB falls back to one thread for short lists). The order is total
  // (ties by texture id, ids are unique after the merge), so the result does not depend on the threads.
  tbb::parallel_sort(out.begin(), out.end(), [](const StreamCandidate& a, const StreamCandidate& b) {
    return a.weight != b.weight ? a.weight > b.weight : a.texture < b.texture;
  });
  if (skipped) *skipped = bad;
  return out;
}

}  // namespace texstream::render
