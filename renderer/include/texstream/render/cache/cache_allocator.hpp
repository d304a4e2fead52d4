#pragma once
// Placement of textures in the cache image (seed 000 §3.6). Each array layer is designated to one maximum
// texture extent E = max(w, h) (rounded up to a power of two) and split into (layer_extent / E)^2 square
// regions, filled left to right, top to bottom, one texture per region. A texture whose extent has no open
// layer takes the next layer in ring order; once every layer has been assigned, the oldest one is recycled and
// the textures in it are evicted (the caller invalidates them). The GPU memory budget can also force the
// oldest layer out early (evict_oldest). Layers are always assigned and freed in ring order, so the live
// layers are the last live_layers() assigned ones: recycling and budget eviction agree on which is oldest.
// Pure bookkeeping: no Vulkan, one thread.
#include <cstdint>
#include <optional>
#include <unordered_map>
#include <vector>

#include "texstream/common/ids.hpp"
#include "texstream/common/result.hpp"

namespace texstream::render {

struct CacheRegion {
  uint32_t layer = 0;
  uint32_t index = 0;     // region within the layer, row-major
  uint32_t origin_x = 0;  // texels at mip 0
  uint32_t origin_y = 0;
  uint32_t extent = 0;  // side of the square region at mip 0
  // The rectangle the texture's texels take at mip 0 (its pages are bound under this): the whole square for
  // the seed's ring, pow2(w) x pow2(h) for QuadtreeAllocator.
  uint32_t width = 0;
  uint32_t height = 0;
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
  // Frees the oldest live layer (ring order) and appends its textures to `evicted`. Returns its index, or
  // nullopt when no layer is live. Used when the page budget (cache.memory_bytes) is full.
  std::optional<uint32_t> evict_oldest(std::vector<TextureId>& evicted);

  uint32_t layer_extent() const { return layer_extent_; }
  uint32_t layers() const { return static_cast<uint32_t>(layers_.size()); }
  uint64_t resident_textures() const { return placed_.size(); }
  uint64_t layers_recycled() const { return recycled_; }
  uint32_t live_layers() const { return static_cast<uint32_t>(assignments_ - oldest_); }
  // Layers are numbered in the order they are assigned (0, 1, ...); layer number k is live while
  // layers_freed() <= k < layers_assigned(), since they are freed in the same order.
  uint64_t layers_assigned() const { return assignments_; }
  uint64_t layers_freed() const { return oldest_; }

 private:
  struct Layer {
    uint32_t extent = 0;  // 0: never assigned
    uint32_t next_index = 0;
    std::vector<TextureId> textures;
  };
  uint32_t take_layer(uint32_t extent, std::vector<TextureId>& evicted);
  void clear_layer(uint32_t layer, std::vector<TextureId>& evicted);

  uint32_t layer_extent_;
  std::vector<Layer> layers_;
  uint64_t assignments_ = 0;  // layers handed out so far; the next is assignments_ % layers
  uint64_t oldest_ = 0;       // assignment number of the oldest live layer
  uint64_t recycled_ = 0;
  std::unordered_map<uint32_t, uint32_t> open_;  // extent -> layer that still has free regions
  std::unordered_map<TextureId, CacheRegion> placed_;
};

}  // namespace texstream::render
