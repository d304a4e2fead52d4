#include "texstream/render/cache/cache_geometry.hpp"

#include <algorithm>
#include <bit>
#include <string>

namespace texstream::render {

uint64_t cache_layer_bytes(TexelFormat format, uint32_t extent) {
  // Each level of each layer starts on a sparse block (64 KiB on lavapipe and the GPUs we know): a 512² RGBA8
  // layer is 1.81 MiB, not the 1.33 MiB of its texels (lavapipe reports 1.75 MiB).
  constexpr uint64_t kBlock = 64u << 10;
  uint64_t total = 0;
  for (uint32_t level = 0; (extent >> level) > 0; ++level)
    total += (mip_bytes(format, extent, extent, level) + kBlock - 1) / kBlock * kBlock;
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
    // The side (up to the cap, never below what the scene needs) whose layers address the most, up to the
    // target: on lavapipe (2 GiB) a 1.5 GiB RGBA8 budget gets 22 layers of 4 K (1.8 GiB), where one 16 K layer
    // (1.4 GiB) would address less than the budget. Near-ties go to the larger side (fewer layers).
    uint64_t best = 0;
    for (uint32_t side = std::min(kLruLayerCap, device_side); side >= needed && side >= 4; side /= 2) {
      const uint64_t bytes = cache_layer_bytes(in.format, side);
      uint64_t count =
          in.layers ? in.layers : std::clamp<uint64_t>(target / bytes, 1, std::max(in.max_array_layers, 1u));
      if (count * bytes > space) continue;
      const uint64_t total = std::min(count * bytes, target);
      if (total > best + best / 16) best = total, g.layer_extent = side;  // a smaller side must gain > 1/16
    }
    if (g.layer_extent == 0) g.layer_extent = std::min(needed, device_side);  // nothing fits: reported below
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
