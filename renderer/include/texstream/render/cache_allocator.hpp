#pragma once
// Placement of textures in the cache image (seed 000 §3.6). Each array layer is designated to one maximum
// texture extent E = max(w, h) (rounded up to a power of two) and split into (layer_extent / E)^2 square
// regions, filled left to right, top to bottom, one texture per region. A texture whose extent has no open
// layer takes the next layer in ring order; once every layer has been assigned, the oldest one is recycled and
// the textures in it are evicted (the caller invalidates them). Pure bookkeeping: no Vulkan, one thread.
#include <cstdint>
#include <optional>
#include <unordered_map>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/protocol/ids.hpp"

namespace texstream::render {

struct CacheRegion {
  uint32_t layer = 0;
  uint32_t index = 0;     // region within the layer, row-major
  uint32_t origin_x = 0;  // texels at mip 0
  uint32_t origin_y = 0;
  uint32_t extent = 0;    // side of the square region at mip 0
};

class CacheAllocator {
 public:
  CacheAllocator(uint32_t layer_extent, uint32_t layers);

  // The square region side a w x h texture needs: the next power of two of max(w, h).
  static uint32_t region_extent(uint32_t width, uint32_t height);

  // A region for `texture` (which must not hold one). Textures of a recycled layer are appended to `evicted`
  // and forgotten. Error if the texture is larger than a layer.
  Result<CacheRegion> allocate(TextureId texture, uint32_t width, uint32_t height, std::vector<TextureId>& evicted);
  std::optional<CacheRegion> find(TextureId texture) const;

  uint32_t layer_extent() const { return layer_extent_; }
  uint32_t layers() const { return static_cast<uint32_t>(layers_.size()); }
  uint64_t resident_textures() const { return placed_.size(); }
  uint64_t layers_recycled() const { return recycled_; }

 private:
  struct Layer {
    uint32_t extent = 0;  // 0: never assigned
    uint32_t next_index = 0;
    std::vector<TextureId> textures;
  };
  uint32_t take_layer(uint32_t extent, std::vector<TextureId>& evicted);

  uint32_t layer_extent_;
  std::vector<Layer> layers_;
  uint64_t assignments_ = 0;                      // layers handed out so far; the next is assignments_ % layers
  uint64_t recycled_ = 0;
  std::unordered_map<uint32_t, uint32_t> open_;   // extent -> layer that still has free regions
  std::unordered_map<TextureId, CacheRegion> placed_;
};

}  // namespace texstream::render
