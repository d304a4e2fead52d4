#pragma once
// One load the renderer asked for, as the dispatcher schedules it and the loader answers it: a mip of a texture
// (kLoad) or a page of a page file (kLoadPage). Both share the scheduler's heap, its generations and the
// worker pools; key() keeps them apart.
#include <cstdint>

#include "texstream/common/contract.hpp"
#include "texstream/common/ids.hpp"
#include "texstream/common/page_file.hpp"
#include "texstream/server/cache/mip_key.hpp"

namespace texstream::server {

// The scheduler's key of a page: its file in the texture half, its absolute index in the quadtree
// (PageGeometry::slot) with the top bit set in the mip half. A mip level is < 32, so no page key is a mip's;
// a page file has at most 16 levels (2^18 texels over pages of at least 8: kMaxVirtualExtent,
// kMinPageTexels), so the index, < (4^16 - 1) / 3, fits the other 31 bits. Not a key of the RAM cache: pages
// are not cached there.
inline MipKey page_key(uint32_t file, pages::PageId page) {
  const uint64_t slot = pages::PageGeometry::first_slot(page.level) + (uint64_t{page.y} << page.level) + page.x;
  TS_ASSERT(page.level < 16 && slot < (1ull << 31), "page key of level %u out of range", page.level);
  return MipKey(TextureId(file), MipLevel(0x80000000u | static_cast<uint32_t>(slot)));
}

struct LoadRequest {
  TextureId texture;  // a mip's texture, or a page's file index (0 = the scene's ground)
  MipLevel mip;       // a mip's level, or a page's level
  Generation generation;
  float priority = 0;        // larger = sooner; finite (the dispatcher drops NaN)
  bool page = false;         // a page (kLoadPage) at (mip, x, y) of page file `texture`, not a mip
  uint64_t received_ns = 0;  // steady clock when taken off the ring (latency statistics only)
  uint32_t x = 0, y = 0;     // a page's position in its level

  // A page's key needs its level below 16 (checked by the dispatcher before it queues the page).
  MipKey key() const { return page ? page_key(texture.value, page_id()) : MipKey(texture, mip); }
  pages::PageId page_id() const { return pages::PageId{mip.value, x, y}; }
};

}  // namespace texstream::server
