#pragma once
// From the compacted per-mesh metadata (seed 000 §3.3) to the per-texture candidate list of a streaming
// cycle: meshes that share a texture merge (finest mip, summed weight), then the list is sorted by weight,
// descending (ties by texture id, so runs are reproducible).
#include <cstdint>
#include <span>
#include <vector>

#include "texstream/common/scene_format.hpp"
#include "texstream/render/gpu_structs.hpp"
#include "texstream/render/texture_states.hpp"

namespace texstream::render {

// `entries` come from the GPU: mesh ids out of range are skipped (counted in `skipped` if given).
std::vector<StreamCandidate> build_candidates(std::span<const gpu::CompactEntry> entries,
                                              std::span<const scene::MeshRecord> meshes,
                                              uint64_t* skipped = nullptr);

}  // namespace texstream::render
