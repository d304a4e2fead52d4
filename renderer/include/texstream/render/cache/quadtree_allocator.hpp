#pragma once
// Placement of textures in the cache image for cache.eviction = lru (docs/design/cache_budget.md): a 2D buddy
// allocator per array layer. A layer is a quadtree of power-of-two squares; a w x h texture takes a rectangle
// of pow2(w) x pow2(h) texels at its top-left corner of the smallest square that holds it, and the quarters of
// that square the rectangle does not cover go back to the free lists at once, so a 2048x1024 texture takes
// 2048x1024 of address space, not 2048². Freed squares merge with their three siblings when those are free,
// so textures of every size share layers and a freed region is reused by any size that fits it.
//
// Free squares are kept per size in order of (layer, Morton code), and the lowest is taken: textures placed
// together end up next to each other, so small ones share sparse pages and leave them together.
//
// Unlike CacheAllocator (the seed's ring) this never evicts by itself: allocate() answers "no room" and the
// caller frees textures it chooses (least recently used) and tries again. Pure bookkeeping: no Vulkan, one
// thread.
#include <cstdint>
#include <optional>
#include <set>
#include <unordered_map>
#include <vector>

#include "texstream/common/ids.hpp"
#include "texstream/render/cache/cache_allocator.hpp"

namespace texstream::render {

class QuadtreeAllocator {
 public:
  // `min_side`: the smallest rectangle side handed out (4 for BC1: one block), a power of two.
  QuadtreeAllocator(uint32_t layer_extent, uint32_t layers, uint32_t min_side);

  // The rectangle a w x h texture takes: pow2(max(w, min_side)) x pow2(max(h, min_side)).
  static std::pair<uint32_t, uint32_t> rect_of(uint32_t width, uint32_t height, uint32_t min_side);

  // A region for `texture` (which must not hold one), or nullopt when no free square is large enough. The
  // caller checks that the texture fits a layer at all (fits()).
  std::optional<CacheRegion> allocate(TextureId texture, uint32_t width, uint32_t height);
  bool fits(uint32_t width, uint32_t height) const;
  // Gives the texture's region back. No-op for a texture without one.
  void free(TextureId texture);
  std::optional<CacheRegion> find(TextureId texture) const;

  uint32_t layer_extent() const { return layer_extent_; }
  uint32_t layers() const { return layers_; }
  uint64_t resident_textures() const { return placed_.size(); }
  // Texels of mip 0 held by regions; the rest of layers x layer_extent² is free (possibly fragmented).
  uint64_t used_texels() const { return used_texels_; }
  // Free squares, all sizes (a measure of fragmentation next to used_texels()).
  uint64_t free_squares() const;

 private:
  // A square: its level (0 = a whole layer, side layer_extent >> level), layer and Morton code at that level.
  struct Square {
    uint32_t level;
    uint32_t layer;
    uint64_t morton;
  };
  struct Placement {
    CacheRegion region;
    std::vector<Square> squares;  // what free() gives back
  };
  static uint64_t key(uint32_t layer, uint64_t morton) { return (uint64_t{layer} << 36) | morton; }
  uint32_t side(uint32_t level) const { return layer_extent_ >> level; }
  void insert_free(Square s);  // with merging
  // Splits the square into its rectangle's squares (kept) and the rest (freed).
  void claim(Square s, uint32_t rect_w, uint32_t rect_h, std::vector<Square>& kept);

  uint32_t layer_extent_;
  uint32_t layers_;
  uint32_t min_side_;
  uint32_t levels_;                       // level of a min_side square + 1
  std::vector<std::set<uint64_t>> free_;  // per level: key(layer, morton)
  std::unordered_map<TextureId, Placement> placed_;
  uint64_t used_texels_ = 0;
};

}  // namespace texstream::render
