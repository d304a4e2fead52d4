#pragma once
// The shape of the sparse cache image (layer side, layer count) chosen from the device's limits, the memory
// budget and the scene, so that the budget is the cache's only limit (docs/design/cache_budget.md):
//
// * Address space is virtual and cheap; memory is not. A texture takes address space for its whole chain but
//   memory only for the levels loaded, and most textures of a view sit at coarse levels (a 512² texture at
//   level 3 binds 1/64 of its address), so the image is given up to kAddressPerBudget times the budget of
//   address space, within the device's sparse address space (lavapipe: 2 GiB; NVIDIA: 1 TiB) and
//   maxImageArrayLayers. With 4x the lru cache evicted for address space at 17 % of its memory budget
//   (CacheThrash test, RGBA8, 4 MiB): docs/design/cache_budget.md.
// * cache.eviction = lru: layers as large as the device allows up to kLruLayerCap, filled by the quadtree
//   allocator with textures of every size. ring (seed 000 §3.6): layers of the scene's largest texture, one
//   size per layer, as many as fit.
// * A value the user set (cache.layer_extent_px, cache.layers: non-zero) is kept as given.
// Pure: no Vulkan.
#include <cstdint>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::render {

struct CacheGeometryInputs {
  CacheEviction eviction = CacheEviction::kLru;
  TexelFormat format = TexelFormat::kRgba8;
  uint32_t layer_extent = 0;          // cache.layer_extent_px; 0: choose
  uint32_t layers = 0;                // cache.layers; 0: choose
  uint64_t memory_bytes = 0;          // cache.memory_bytes
  uint32_t largest_texture = 1;       // max(width, height) over the scene's textures
  uint32_t max_image_dimension = 0;   // VkPhysicalDeviceLimits::maxImageDimension2D
  uint32_t max_array_layers = 0;      // maxImageArrayLayers
  uint64_t sparse_address_space = 0;  // sparseAddressSpaceSize
};

struct CacheGeometry {
  uint32_t layer_extent = 0;
  uint32_t layers = 0;
  uint64_t virtual_bytes = 0;  // estimate of the image's size with every level (layer_bytes x layers)
};

// Address space given per byte of budget when the device has it (see the header comment).
inline constexpr uint64_t kAddressPerBudget = 64;
// Largest automatic layer side for lru: 16 K covers every texture the default profiles can sample, and texel
// coordinates in a layer stay exact to ~1/1000 texel in the shader's float arithmetic.
inline constexpr uint32_t kLruLayerCap = 16384;

// Bytes of one layer of side `extent` with its whole mip chain, each level padded to a 64 KiB sparse block.
uint64_t cache_layer_bytes(TexelFormat format, uint32_t extent);

// Errors name the key to change: a scene texture larger than any layer the device can address.
Result<CacheGeometry> choose_cache_geometry(const CacheGeometryInputs& in);

}  // namespace texstream::render
