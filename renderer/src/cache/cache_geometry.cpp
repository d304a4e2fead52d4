#include "texstream/render/cache/cache_geometry.hpp"

#include <algorithm>
#include <bit>
#include <string>

namespace texstream::render {

uint64_t cache_layer_bytes(TexelFormat format, uint32_t extent) {
  uint64_t total = 0;
  for (uint32_t level = 0; (extent >> level) > 0; ++level) total += mip_bytes(format, extent, extent, level);
  return total;
}

Result<CacheGeometry> choose_cache_geometry(const CacheGeometryInputs& in) {
  auto bad = [](const std::string& key, const std::string& msg) {
    return make_error(ErrorCode::kInvalidArgument, "key '" + key + "': " + msg);
  };
  const uint32_t device_side = std::bit_floor(std::max(in.max_image_dimension, 1u));
  const uint32_t needed = std::bit_ceil(std::max(in.largest_texture, 4u));
  // The image may use most of the sparse address space, not all: the device counts other sparse resources
  // (and its own alignment) against the same figure.
  const uint64_t space = in.sparse_address_space / 16 * 15;
  const uint64_t target = std::min(space, std::max<uint64_t>(in.memory_bytes * kAddressPerBudget, 1));

  CacheGeometry g;
  if (in.layer_extent != 0) {
    g.layer_extent = in.layer_extent;
    if (g.layer_extent > device_side) {
      return bad("cache.layer_extent_px", std::to_string(g.layer_extent) +
                                              " exceeds the device's maxImageDimension2D " +
                                              std::to_string(in.max_image_dimension));
    }
  } else if (in.eviction == CacheEviction::kRing) {
    g.layer_extent = std::min(needed, device_side);  // seed §3.6: a layer is one texture of the largest size
  } else {
    // The largest side up to the cap whose layers (in.layers of them when the user set the count) fit the
    // target; never below what the scene needs.
    const uint64_t count = std::max(in.layers, 1u);
    g.layer_extent = std::min(kLruLayerCap, device_side);
    while (g.layer_extent > needed && cache_layer_bytes(in.format, g.layer_extent) * count > target)
      g.layer_extent /= 2;
  }
  if (in.largest_texture > g.layer_extent && in.layer_extent == 0) {
    return bad("cache.layer_extent_px", "the scene's largest texture (" + std::to_string(in.largest_texture) +
                                            " px) exceeds the device's maxImageDimension2D " +
                                            std::to_string(in.max_image_dimension));
  }
  const uint64_t layer = cache_layer_bytes(in.format, g.layer_extent);
  if (in.layers != 0) {
    g.layers = in.layers;
  } else {
    const uint64_t fit = std::min<uint64_t>(target / layer, space / layer);
    g.layers = static_cast<uint32_t>(std::clamp<uint64_t>(fit, 1, std::max(in.max_array_layers, 1u)));
  }
  g.virtual_bytes = layer * g.layers;
  if (g.virtual_bytes > space) {
    return bad(in.layers ? "cache.layers" : "cache.layer_extent_px",
               std::to_string(g.layers) + " layers of " + std::to_string(g.layer_extent) + " px need " +
                   std::to_string(g.virtual_bytes >> 20) + " MiB of sparse address space; the device has " +
                   std::to_string(in.sparse_address_space >> 20) + " MiB");
  }
  return g;
}

}  // namespace texstream::render
