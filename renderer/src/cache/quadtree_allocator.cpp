#include "texstream/render/cache/quadtree_allocator.hpp"

#include <algorithm>
#include <bit>

#include "texstream/common/contract.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::render {

namespace {

uint32_t pow2_ceil(uint32_t v) { return v <= 1 ? 1 : std::bit_ceil(v); }

// Every other bit of a Morton code: x sits in the even bits, y in the odd ones.
uint32_t compact_bits(uint64_t m) {
  m &= 0x5555555555555555ull;
  m = (m | (m >> 1)) & 0x3333333333333333ull;
  m = (m | (m >> 2)) & 0x0f0f0f0f0f0f0f0full;
  m = (m | (m >> 4)) & 0x00ff00ff00ff00ffull;
  m = (m | (m >> 8)) & 0x0000ffff0000ffffull;
  m = (m | (m >> 16)) & 0x00000000ffffffffull;
  return static_cast<uint32_t>(m);
}

}  // namespace

QuadtreeAllocator::QuadtreeAllocator(uint32_t layer_extent, uint32_t layers, uint32_t min_side)
    : layer_extent_(layer_extent), layers_(layers), min_side_(min_side) {
  TS_ASSERT(layers > 0, "cache with no layers");
  TS_ASSERT(std::has_single_bit(layer_extent) && std::has_single_bit(min_side) && min_side <= layer_extent,
            "layer extent %u / smallest side %u not powers of two", layer_extent, min_side);
  // Morton codes of the smallest squares take 2 bits per level below the layer: 36 bits leave 18 levels.
  levels_ = floor_log2(layer_extent / min_side) + 1;
  TS_ASSERT(levels_ <= 18, "layer extent %u too large for the allocator's keys", layer_extent);
  free_.resize(levels_);
  for (uint32_t l = 0; l < layers; ++l) free_[0].insert(key(l, 0));
}

std::pair<uint32_t, uint32_t> QuadtreeAllocator::rect_of(uint32_t width, uint32_t height, uint32_t min_side) {
  return {pow2_ceil(std::max(width, min_side)), pow2_ceil(std::max(height, min_side))};
}

bool QuadtreeAllocator::fits(uint32_t width, uint32_t height) const {
  if (width == 0 || height == 0) return false;
  const auto [w, h] = rect_of(width, height, min_side_);
  return std::max(w, h) <= layer_extent_;
}

void QuadtreeAllocator::insert_free(Square s) {
  while (s.level > 0) {
    std::set<uint64_t>& level = free_[s.level];
    const uint64_t first = s.morton & ~uint64_t{3};
    bool siblings_free = true;
    for (uint64_t i = 0; i < 4 && siblings_free; ++i) {
      if (first + i != s.morton) siblings_free = level.count(key(s.layer, first + i)) != 0;
    }
    if (!siblings_free) break;
    for (uint64_t i = 0; i < 4; ++i) {
      if (first + i != s.morton) level.erase(key(s.layer, first + i));
    }
    s = Square{s.level - 1, s.layer, s.morton >> 2};
  }
  free_[s.level].insert(key(s.layer, s.morton));
}

void QuadtreeAllocator::claim(Square s, uint32_t rect_w, uint32_t rect_h, std::vector<Square>& kept) {
  const uint32_t sd = side(s.level);
  if (rect_w >= sd && rect_h >= sd) {
    kept.push_back(s);
    return;
  }
  // The rectangle sits at the square's top-left corner: quarter (dx, dy) holds min(rect - d * half, half).
  const uint32_t half = sd / 2;
  for (uint32_t q = 0; q < 4; ++q) {
    const uint32_t dx = q & 1u, dy = q >> 1;
    const Square child{s.level + 1, s.layer, s.morton * 4 + q};
    const uint32_t cw = rect_w > dx * half ? std::min(rect_w - dx * half, half) : 0;
    const uint32_t ch = rect_h > dy * half ? std::min(rect_h - dy * half, half) : 0;
    if (cw == 0 || ch == 0) {
      free_[child.level].insert(key(child.layer, child.morton));  // its siblings are in use: no merge
    } else {
      claim(child, cw, ch, kept);
    }
  }
}

std::optional<CacheRegion> QuadtreeAllocator::allocate(TextureId texture, uint32_t width, uint32_t height) {
  TS_ASSERT(!placed_.count(texture), "texture %u already has a cache region", texture.value);
  TS_ASSERT(fits(width, height), "texture %u (%ux%u) larger than a layer", texture.value, width, height);
  const auto [rw, rh] = rect_of(width, height, min_side_);
  const uint32_t want = floor_log2(layer_extent_ / std::max(rw, rh));
  // The smallest free square that holds the rectangle: this size, else split the nearest larger one.
  int32_t from = static_cast<int32_t>(want);
  while (from >= 0 && free_[static_cast<uint32_t>(from)].empty()) --from;
  if (from < 0) return std::nullopt;
  std::set<uint64_t>& src = free_[static_cast<uint32_t>(from)];
  const uint64_t k = *src.begin();
  src.erase(src.begin());
  Square s{static_cast<uint32_t>(from), static_cast<uint32_t>(k >> 36), k & ((uint64_t{1} << 36) - 1)};
  // Split down to the wanted size: each level's three other quarters go to that level's free list.
  while (s.level < want) {
    for (uint64_t q = 1; q < 4; ++q) free_[s.level + 1].insert(key(s.layer, s.morton * 4 + q));
    s = Square{s.level + 1, s.layer, s.morton * 4};
  }
  Placement p;
  claim(s, rw, rh, p.squares);
  const uint32_t sd = side(s.level);
  p.region.layer = s.layer;
  p.region.index = 0;
  p.region.origin_x = compact_bits(s.morton) * sd;
  p.region.origin_y = compact_bits(s.morton >> 1) * sd;
  p.region.extent = sd;
  p.region.width = rw;
  p.region.height = rh;
  used_texels_ += uint64_t{rw} * rh;
  const CacheRegion r = p.region;
  placed_.emplace(texture, std::move(p));
  return r;
}

void QuadtreeAllocator::free(TextureId texture) {
  auto it = placed_.find(texture);
  if (it == placed_.end()) return;
  used_texels_ -= uint64_t{it->second.region.width} * it->second.region.height;
  for (const Square& s : it->second.squares) insert_free(s);
  placed_.erase(it);
}

std::optional<CacheRegion> QuadtreeAllocator::find(TextureId texture) const {
  auto it = placed_.find(texture);
  if (it == placed_.end()) return std::nullopt;
  return it->second.region;
}

uint64_t QuadtreeAllocator::free_squares() const {
  uint64_t n = 0;
  for (const auto& l : free_) n += l.size();
  return n;
}

}  // namespace texstream::render
