#include "texstream/render/cache/residency_table.hpp"

#include "texstream/common/contract.hpp"

namespace texstream::render {

ResidencyTable::ResidencyTable(size_t texture_count, size_t expected_entries)
    : index_(expected_entries), evicted_before_(texture_count, false) {}

Residency* ResidencyTable::find(TextureId texture) {
  const uint32_t i = index_.find(texture);
  return i == TextureIndexMap::kAbsent ? nullptr : &at(i);
}

const Residency* ResidencyTable::find(TextureId texture) const {
  const uint32_t i = index_.find(texture);
  return i == TextureIndexMap::kAbsent ? nullptr : &at(i);
}

Residency& ResidencyTable::get(TextureId texture) {
  if (Residency* r = find(texture)) return *r;
  uint32_t i;
  if (!free_.empty()) {
    i = free_.back();
    free_.pop_back();
  } else {
    TS_ASSERT(pool_entries_ < UINT32_MAX, "residency pool full");
    i = pool_entries_++;
    if ((i >> kChunkShift) == chunks_.size()) chunks_.push_back(std::make_unique<Residency[]>(kChunk));
  }
  Residency& r = at(i);
  r = Residency{};
  r.epoch = new_epoch();
  r.texture_ = texture.value;
  r.index_ = i;
  index_.insert(texture, i);
  return r;
}

bool ResidencyTable::release_if_idle(Residency& r) {
  if (r.mask != 0 || r.bound != 0 || r.lru_listed_ || r.copies != 0) return false;
  const bool erased = index_.erase(r.texture());
  TS_ASSERT(erased, "residency of texture %u not in its index", r.texture_);
  free_.push_back(r.index_);
  return true;
}

void ResidencyTable::lru_append(Residency& r) {
  TS_ASSERT(!r.lru_listed_, "texture %u listed twice", r.texture_);
  r.lru_prev_ = lru_tail_;
  r.lru_next_ = 0;
  if (lru_tail_)
    at(lru_tail_ - 1).lru_next_ = r.index_ + 1;
  else
    lru_head_ = r.index_ + 1;
  lru_tail_ = r.index_ + 1;
  r.lru_listed_ = true;
}

void ResidencyTable::lru_unlink(Residency& r) {
  if (!r.lru_listed_) return;
  if (r.lru_prev_)
    at(r.lru_prev_ - 1).lru_next_ = r.lru_next_;
  else
    lru_head_ = r.lru_next_;
  if (r.lru_next_)
    at(r.lru_next_ - 1).lru_prev_ = r.lru_prev_;
  else
    lru_tail_ = r.lru_prev_;
  r.lru_prev_ = r.lru_next_ = 0;
  r.lru_listed_ = false;
}

}  // namespace texstream::render
