#include "texstream/render/cache/staging_ring.hpp"

#include "texstream/common/contract.hpp"

namespace texstream::render {

StagingRing::StagingRing(uint64_t capacity) : capacity_(capacity) { TS_ASSERT(capacity > 0, "empty staging ring"); }

std::optional<StagingRing::Allocation> StagingRing::allocate(uint64_t bytes, uint64_t alignment) {
  TS_ASSERT(alignment > 0 && (alignment & (alignment - 1)) == 0, "alignment %llu", (unsigned long long)alignment);
  if (bytes == 0 || bytes > capacity_) return std::nullopt;
  uint64_t pos = (head_ + alignment - 1) & ~(alignment - 1);
  uint64_t offset = pos % capacity_;
  if (offset + bytes > capacity_) {  // does not fit before the end of the buffer: wrap to offset 0
    pos += capacity_ - offset;
    offset = 0;
  }
  if (pos + bytes - tail_ > capacity_) return std::nullopt;
  const uint64_t id = next_id_++;
  entries_.push_back(Entry{id, pos + bytes, false});
  head_ = pos + bytes;
  return Allocation{offset, bytes, id};
}

void StagingRing::release(uint64_t id) {
  bool found = false;
  for (Entry& e : entries_) {
    if (e.id == id) {
      TS_ASSERT(!e.released, "staging allocation %llu released twice", (unsigned long long)id);
      e.released = true;
      found = true;
      break;
    }
  }
  TS_ASSERT(found, "unknown staging allocation %llu", (unsigned long long)id);
  while (!entries_.empty() && entries_.front().released) {
    tail_ = entries_.front().end;
    entries_.pop_front();
  }
  // Nothing live: every byte is free, whatever the positions were, so start again at offset 0.
  if (entries_.empty()) head_ = tail_ = 0;
}

}  // namespace texstream::render
