#include "texstream/render/frame/visibility_list.hpp"

#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cstdint>

namespace texstream::render {

namespace {

// Lists up to this long are sorted on the calling thread: below it, handing work to TBB's threads costs more
// than the sort (a frame's list is typically a few thousand entries; seed 000 §3.3's parallel sort pays off for
// the hundreds of thousands a city view can hold).
constexpr size_t kParallelSortMin = 1u << 15;

struct TextureSum {
  uint32_t texture;
  uint32_t mip_fixed;
  uint64_t weight_fixed;
};

template <class It, class Less>
void sort_list(It first, It last, Less less) {
  if (static_cast<size_t>(last - first) >= kParallelSortMin) {
    tbb::parallel_sort(first, last, less);
  } else {
    std::sort(first, last, less);
  }
}

}  // namespace

std::vector<stream::StreamCandidate> build_candidates(std::span<const gpu::CompactEntry> entries, size_t mesh_count,
                                                      size_t texture_count, uint64_t* skipped) {
  // Meshes sharing a texture merge by sorting on the texture id and combining neighbours: no hash table and no
  // allocation per entry (this runs on the frame thread every streaming cycle). Weights are summed in the GPU's
  // fixed point (exact, so the sum, and with it the order, does not depend on the order the compaction's
  // atomics wrote the entries in), converted once at the end.
  std::vector<TextureSum> sums;
  sums.reserve(entries.size());
  uint64_t bad = 0;
  for (const gpu::CompactEntry& e : entries) {
    if (e.mesh_id >= mesh_count || e.texture_id >= texture_count || e.mip_fixed == gpu::kNoMip) {
      ++bad;
      continue;
    }
    sums.push_back(TextureSum{e.texture_id, e.mip_fixed, e.weight_fixed});
  }
  sort_list(sums.begin(), sums.end(), [](const TextureSum& a, const TextureSum& b) { return a.texture < b.texture; });
  std::vector<stream::StreamCandidate> out;
  out.reserve(sums.size());
  for (size_t i = 0; i < sums.size();) {
    TextureSum t = sums[i];
    for (++i; i < sums.size() && sums[i].texture == t.texture; ++i) {
      t.mip_fixed = std::min(t.mip_fixed, sums[i].mip_fixed);
      t.weight_fixed += sums[i].weight_fixed;
    }
    out.push_back(stream::StreamCandidate{
        TextureId(t.texture), static_cast<float>(t.mip_fixed) / static_cast<float>(gpu::kMipFixedScale),
        static_cast<float>(static_cast<double>(t.weight_fixed) / gpu::kWeightFixedScale)});
  }
  // Descending weight (seed 000 §3.3), parallel for long lists. The order is total (ties by texture id, ids are
  // unique after the merge), so the result does not depend on the threads.
  sort_list(out.begin(), out.end(), [](const stream::StreamCandidate& a, const stream::StreamCandidate& b) {
    return a.weight != b.weight ? a.weight > b.weight : a.texture < b.texture;
  });
  if (skipped) *skipped = bad;
  return out;
}

}  // namespace texstream::render
