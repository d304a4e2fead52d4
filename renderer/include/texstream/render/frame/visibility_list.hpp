#pragma once
// From the compacted per-mesh metadata (seed 000 §3.3) to the per-texture candidate list of a streaming
// cycle: meshes that share a texture merge (finest mip, summed weight), then the list is sorted by weight,
// descending (ties by texture id, so runs are reproducible).
#include <cstdint>
#include <span>
#include <vector>

#include "texstream/common/scene_format.hpp"
#include "texstream/render/scene/gpu_structs.hpp"
#include "texstream/stream/texture_states.hpp"

namespace texstream::render {

// `entries` come from the GPU, each with its mesh's texture id (compact.comp): entries whose mesh id is not below
// `mesh_count` or texture id not below `texture_count` are skipped (counted in `skipped` if given). The mesh
// records are not read: one random access each was most of this function's time on the frame thread (a cold
// cache line per entry, ~100 ns: 30 of 32 us for 295 entries on lavapipe).
std::vector<stream::StreamCandidate> build_candidates(std::span<const gpu::CompactEntry> entries, size_t mesh_count,
                                                      size_t texture_count, uint64_t* skipped = nullptr);

}  // namespace texstream::render
