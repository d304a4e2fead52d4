#pragma once
// Allocation bookkeeping of the host-visible staging buffer that the stream client copies validated mip
// payloads into (MipSink::reserve). Allocations are carved in ring order; each is released when the GPU copy
// that reads it has finished (or at once if it was never submitted). Space comes back in allocation order, so a
// slow early copy holds back later space but nothing is ever overwritten while the GPU may still read it.
// Pure bookkeeping, one thread.
#include <cstdint>
#include <deque>
#include <optional>

namespace texstream::render {

class StagingRing {
 public:
  struct Allocation {
    uint64_t offset = 0;  // in the buffer
    uint64_t size = 0;
    uint64_t id = 0;  // for release()
  };

  explicit StagingRing(uint64_t capacity);

  // nullopt when `bytes` do not fit now (or ever: bytes > capacity). alignment: a power of two.
  std::optional<Allocation> allocate(uint64_t bytes, uint64_t alignment);
  // The GPU (or nobody) reads allocation `id` no more. Unknown or repeated ids are bugs.
  void release(uint64_t id);

  uint64_t capacity() const { return capacity_; }
  uint64_t used() const { return head_ - tail_; }  // bytes not yet reusable, padding included
  size_t live() const { return entries_.size(); }

 private:
  struct Entry {
    uint64_t id;
    uint64_t end;  // ring position after this allocation
    bool released;
  };
  uint64_t capacity_;
  uint64_t head_ = 0;  // ring positions grow forever; the buffer offset is position % capacity
  uint64_t tail_ = 0;
  uint64_t next_id_ = 1;
  std::deque<Entry> entries_;
};

}  // namespace texstream::render
