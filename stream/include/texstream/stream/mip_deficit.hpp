#pragma once
// The weighted mip deficit of a visibility list (issue 25; docs/design/stream_metrics.md): how many levels
// coarser than wanted the view's textures are drawn, weighted by how much of the view they cover. Unreal's
// "wanted vs visible mips", Unity's "desired vs loaded"; 0 when every listed texture is drawn at its wanted
// level or finer. Pure: no clock, no I/O.
#include <cstdint>
#include <functional>
#include <optional>
#include <span>

#include "texstream/common/ids.hpp"
#include "texstream/stream/texture_states.hpp"

namespace texstream::stream {

// What the shader can sample of one texture: the resident run [finest, coarsest] (TextureCache::publish),
// or nothing (then it draws the texture's colormap colour).
struct ResidentLevels {
  uint32_t mip_count = 0;
  std::optional<uint32_t> finest;  // both set or both empty
  std::optional<uint32_t> coarsest;
};

// The level the deficit counts a texture as drawn at when the view wants level `wanted`:
// max(wanted, finest); with nothing resident, mip_count (one level coarser than its coarsest: only the
// colormap colour is drawn). A wanted level coarser than everything resident is drawn at `wanted` here (no
// deficit), although the shader clamps it to the coarsest resident level.
double displayed_level(double wanted, const ResidentLevels& levels);

// Σ W·max(0, displayed − wanted) / Σ W over `list` (W = weight, wanted = desired_mip, displayed as
// displayed_level with `levels(texture)`). Entries with a non-finite wanted level or a weight that is not
// positive and finite are left out; an empty list (or one with no such entry) has deficit 0: nothing the
// view needs is missing.
double weighted_mip_deficit(std::span<const StreamCandidate> list,
                            const std::function<ResidentLevels(TextureId)>& levels);

}  // namespace texstream::stream
