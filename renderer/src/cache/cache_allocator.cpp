#include "texstream/render/cache/cache_allocator.hpp"

#include <algorithm>
#include <string>

#include "texstream/common/texel_format.hpp"

namespace texstream::render {

CacheAllocator::CacheAllocator(uint32_t layer_extent, uint32_t layers) : layer_extent_(layer_extent), layers_(layers) {
  TS_ASSERT(layers > 0, "cache with no layers");
  TS_ASSERT(layer_extent > 0 && (layer_extent & (layer_extent - 1)) == 0, "layer extent %u is not a power of two",
            layer_extent);
}

uint32_t CacheAllocator::region_extent(uint32_t width, uint32_t height) {
  const uint32_t e = std::max(width, height);
  const uint32_t log = floor_log2(e);
  return (1u << log) == e ? e : 2u << log;
}

void CacheAllocator::clear_layer(uint32_t layer, std::vector<TextureId>& evicted) {
  Layer& l = layers_[layer];
  for (TextureId t : l.textures) {
    placed_.erase(t);
    evicted.push_back(t);
  }
  // It stops being the open layer of its extent.
  auto it = open_.find(l.extent);
  if (it != open_.end() && it->second == layer) open_.erase(it);
  l = Layer{};
}

uint32_t CacheAllocator::take_layer(uint32_t extent, std::vector<TextureId>& evicted) {
  const auto layer = static_cast<uint32_t>(assignments_ % layers_.size());
  if (assignments_ - oldest_ == layers_.size()) {
    // Every layer is live: the next in ring order is the oldest; recycling it evicts everything in it.
    ++recycled_;
    clear_layer(layer, evicted);
    ++oldest_;
  }
  ++assignments_;
  layers_[layer] = Layer{extent, 0, {}};
  open_[extent] = layer;
  return layer;
}

std::optional<uint32_t> CacheAllocator::evict_oldest(std::vector<TextureId>& evicted) {
  if (assignments_ == oldest_) return std::nullopt;
  const auto layer = static_cast<uint32_t>(oldest_ % layers_.size());
  ++recycled_;
  clear_layer(layer, evicted);
  ++oldest_;
  return layer;
}

Result<CacheRegion> CacheAllocator::allocate(TextureId texture, uint32_t width, uint32_t height,
                                             std::vector<TextureId>& evicted) {
  TS_ASSERT(!placed_.count(texture), "texture %u already has a cache region", texture.value);
  const uint32_t extent = region_extent(width, height);
  if (width == 0 || height == 0 || extent > layer_extent_) {
    return make_error(ErrorCode::kInvalidArgument,
                      "texture " + std::to_string(texture.value) + " (" + std::to_string(width) + "x" +
                          std::to_string(height) +
                          ") does not fit a cache layer of cache.layer_extent_px = " + std::to_string(layer_extent_));
  }
  const uint32_t per_row = layer_extent_ / extent;
  const uint32_t capacity = per_row * per_row;
  auto it = open_.find(extent);
  uint32_t layer = it != open_.end() ? it->second : take_layer(extent, evicted);
  if (layers_[layer].next_index >= capacity) layer = take_layer(extent, evicted);
  Layer& l = layers_[layer];
  CacheRegion r;
  r.layer = layer;
  r.index = l.next_index++;
  r.origin_x = (r.index % per_row) * extent;
  r.origin_y = (r.index / per_row) * extent;
  r.extent = extent;
  r.width = r.height = extent;
  l.textures.push_back(texture);
  if (l.next_index >= capacity) open_.erase(extent);  // full: the next texture of this extent opens a new layer
  placed_.emplace(texture, r);
  return r;
}

std::optional<CacheRegion> CacheAllocator::find(TextureId texture) const {
  auto it = placed_.find(texture);
  if (it == placed_.end()) return std::nullopt;
  return it->second;
}

}  // namespace texstream::render
