#include "texstream/render/cache/sparse_page_table.hpp"

#include <algorithm>

#include "texstream/common/contract.hpp"

namespace texstream::render {

SparsePageTable::SparsePageTable(const PageGeometry& geometry, uint32_t slot_count)
    : SparsePageTable(std::vector<PageGeometry>{geometry}, slot_count) {}

SparsePageTable::SparsePageTable(std::vector<PageGeometry> images, uint32_t slot_count)
    : geometries_(std::move(images)), slot_count_(slot_count) {
  TS_ASSERT(!geometries_.empty() && geometries_.size() <= kMaxCacheImages, "%zu cache images", geometries_.size());
  for (const PageGeometry& geometry : geometries_) {
    TS_ASSERT(geometry.granularity_w > 0 && geometry.granularity_h > 0, "sparse page granularity of zero");
    TS_ASSERT(geometry.layer_extent > 0 && geometry.mip_levels > 0 && geometry.mip_levels <= 32, "bad cache geometry");
    // Keys pack image, layer and level into the upper word and the page column and row into 16 bits each.
    TS_ASSERT(geometry.layers <= (1u << 24) && geometry.layer_extent / geometry.granularity_w < 65536 &&
                  geometry.layer_extent / geometry.granularity_h < 65536,
              "cache geometry too large for page keys");
  }
  free_.resize(slot_count);
  for (uint32_t i = 0; i < slot_count; ++i) free_[i] = slot_count - 1 - i;
}

uint64_t SparsePageTable::key(uint32_t image, uint32_t layer, uint32_t mip, uint32_t x, uint32_t y) const {
  return (static_cast<uint64_t>(image) << 61) | (static_cast<uint64_t>(layer) << 37) |
         (static_cast<uint64_t>(mip) << 32) | (static_cast<uint64_t>(x) << 16) | y;
}

PageLocation SparsePageTable::location(uint64_t k) const {
  return PageLocation{static_cast<uint32_t>((k >> 37) & 0xffffffu), static_cast<uint32_t>((k >> 32) & 31u),
                      static_cast<uint32_t>((k >> 16) & 0xffffu), static_cast<uint32_t>(k & 0xffffu),
                      static_cast<uint32_t>(k >> 61)};
}

template <class F>
void SparsePageTable::for_each_page(const PageRect& r, uint32_t mip, F&& f) const {
  TS_ASSERT(r.image < geometries_.size(), "page of image %u of %zu", r.image, geometries_.size());
  const PageGeometry& g = geometries_[r.image];
  TS_ASSERT(r.layer < g.layers && mip < g.mip_levels, "page of layer %u mip %u outside the image", r.layer, mip);
  if (mip >= g.tail_first_level) return;  // the mip tail is bound for good at start-up
  const uint32_t x0 = r.x >> mip, y0 = r.y >> mip;
  const uint32_t w = std::max(r.width >> mip, r.block), h = std::max(r.height >> mip, r.block);
  const uint32_t gw = g.granularity_w, gh = g.granularity_h;
  for (uint32_t py = y0 / gh; py <= (y0 + h - 1) / gh; ++py)
    for (uint32_t px = x0 / gw; px <= (x0 + w - 1) / gw; ++px) f(key(r.image, r.layer, mip, px, py));
}

uint32_t SparsePageTable::pages_of_region(const PageGeometry& g, const PageRect& r, uint32_t mip) {
  if (mip >= g.tail_first_level) return 0;
  const uint32_t x0 = r.x >> mip, y0 = r.y >> mip;
  const uint32_t w = std::max(r.width >> mip, r.block), h = std::max(r.height >> mip, r.block);
  const uint32_t cols = (x0 + w - 1) / g.granularity_w - x0 / g.granularity_w + 1;
  const uint32_t rows = (y0 + h - 1) / g.granularity_h - y0 / g.granularity_h + 1;
  return cols * rows;
}

bool SparsePageTable::acquire(const PageRect& rect, uint32_t mip) {
  // Count first, so that a refusal leaves everything as it was.
  uint32_t needed = 0;
  for_each_page(rect, mip, [&](uint64_t k) { needed += pages_.count(k) == 0; });
  if (needed > free_.size()) {
    ++stats_.acquire_failures;
    return false;
  }
  for_each_page(rect, mip, [&](uint64_t k) {
    auto [it, inserted] = pages_.try_emplace(k);
    Page& p = it->second;
    if (inserted) {
      p.slot = free_.back();
      free_.pop_back();
      batch_[k] = Op{true, p.slot};
    } else if (p.refs == 0) {
      // Retired but not yet unbound: still bound to its slot, so it only needs its reference back. Its texels
      // are stale, but only the region about to be copied will be sampled.
      --retired_count_;
      ++stats_.pages_revived;
    } else {
      ++stats_.pages_shared;
    }
    ++p.refs;
  });
  return true;
}

void SparsePageTable::release(const PageRect& rect, uint32_t mip, uint64_t serial) {
  for_each_page(rect, mip, [&](uint64_t k) {
    auto it = pages_.find(k);
    TS_ASSERT(it != pages_.end() && it->second.refs > 0, "release of a page that holds no reference");
    Page& p = it->second;
    if (--p.refs == 0) {
      p.retire_serial = serial;
      ++retired_count_;
    }
  });
}

uint32_t SparsePageTable::reclaim(uint64_t completed_serial) {
  if (retired_count_ == 0) return 0;
  uint32_t freed = 0;
  // Retired pages are few compared with the referenced ones only in steady state; a layer eviction retires a
  // whole layer at once. One pass over the map per reclaim keeps this simple and is O(referenced pages).
  for (auto it = pages_.begin(); it != pages_.end();) {
    Page& p = it->second;
    if (p.refs != 0 || p.retire_serial > completed_serial) {
      ++it;
      continue;
    }
    free_.push_back(p.slot);
    batch_[it->first] = Op{false, 0};
    --retired_count_;
    ++freed;
    it = pages_.erase(it);
  }
  // Keep the lowest free slot on top so memory blocks fill in order and the later ones may stay unallocated.
  if (freed) std::sort(free_.begin(), free_.end(), std::greater<>());
  return freed;
}

std::vector<PageBindOp> SparsePageTable::take_batch() {
  std::vector<PageBindOp> out;
  out.reserve(batch_.size());
  for (const auto& [k, op] : batch_) {
    if (op.bind) {
      out.push_back(PageBindOp{location(k), true, op.slot});
      device_bound_.insert(k);
      ++stats_.pages_bound;
    } else if (device_bound_.erase(k)) {
      out.push_back(PageBindOp{location(k), false, 0});
      ++stats_.pages_unbound;
    }
    // else: bound and released within this batch, never reached the device.
  }
  batch_.clear();
  TS_ASSERT(device_bound_.size() <= slot_count_, "%zu pages bound with %u slots", device_bound_.size(), slot_count_);
  // Deterministic order (the map's is not): by image, layer, level, row, column.
  std::sort(out.begin(), out.end(), [](const PageBindOp& a, const PageBindOp& b) {
    if (a.page.image != b.page.image) return a.page.image < b.page.image;
    if (a.page.layer != b.page.layer) return a.page.layer < b.page.layer;
    if (a.page.mip != b.page.mip) return a.page.mip < b.page.mip;
    if (a.page.y != b.page.y) return a.page.y < b.page.y;
    return a.page.x < b.page.x;
  });
  return out;
}

}  // namespace texstream::render
