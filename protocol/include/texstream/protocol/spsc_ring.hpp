#pragma once
// Single-producer single-consumer ring over memory in the shared segment (iceoryx spsc_fifo style).
//
// Positions increase forever (uint64_t never wraps in practice) and index the record array modulo the
// capacity, a power of two. The producer is the only writer of `write_pos` and of the records; the consumer
// is the only writer of `read_pos`. Each side keeps its own position in process memory as the truth and only
// *publishes* it to the segment, so a hostile or corrupted peer can never move our own position; the peer's
// published position is validated on every load (it must lie in [ours - capacity, ours] or [ours, ours +
// capacity]) and a violation is a protocol error, never an out-of-bounds access.
//
// No locks, no waiting: every call returns at once. Safe against a peer killed at any instant: a record is
// visible only after the release-store of the position that follows its full copy.
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <optional>
#include <type_traits>

#include "texstream/common/contract.hpp"
#include "texstream/protocol/shm_atomic.hpp"

namespace texstream {

// Lives in the segment. The two positions sit on separate cache lines: they have different writers.
struct RingControl {
  alignas(64) ShmAtomic<uint64_t> write_pos;  // written by the producer only
  alignas(64) ShmAtomic<uint64_t> read_pos;   // written by the consumer only
};
static_assert(sizeof(RingControl) == 128);

enum class RingError { kNone, kPeerCorrupt };

template <class Record>
class SpscRingProducer {
  static_assert(std::is_trivially_copyable_v<Record>);

 public:
  SpscRingProducer() = default;
  // `control` and `records` point into the segment; `capacity` is a power of two. Resumes from the published
  // write position (a ring handed over after a peer restart has been reset to zero by its owner).
  SpscRingProducer(RingControl* control, Record* records, uint32_t capacity)
      : control_(control), records_(records), capacity_(capacity) {
    TS_ASSERT(capacity != 0 && (capacity & (capacity - 1)) == 0, "ring capacity %u is not a power of two", capacity);
    // relaxed: only this process writes write_pos; at construction no other thread of ours touches it.
    write_pos_ = control_->write_pos.v.load(std::memory_order_relaxed);
  }

  // Producer thread only. Returns false when full (or when the consumer's published position is impossible:
  // then error() says so and the ring refuses further pushes).
  bool try_push(const Record& record) {
    if (error_ != RingError::kNone) return false;
    // acquire: pairs with the consumer's release-store of read_pos, so its reads of the slot we reuse are done.
    const uint64_t read = control_->read_pos.v.load(std::memory_order_acquire);
    if (read > write_pos_ || write_pos_ - read > capacity_) {
      error_ = RingError::kPeerCorrupt;
      return false;
    }
    if (write_pos_ - read == capacity_) return false;
    copy_record(record);
    ++write_pos_;
    // release: pairs with the consumer's acquire-load of write_pos; publishes the record copied above.
    control_->write_pos.v.store(write_pos_, std::memory_order_release);
    return true;
  }

  // Producer thread only. Like try_push(), but the record stays invisible to the consumer until publish()
  // (or a later try_push(), which publishes everything before it): a producer with a burst of records pays
  // one release-store of write_pos per burst instead of one per record, and looks at the consumer's read
  // position only when the ring seems full with the position it last saw (read_pos only grows, so an old
  // reading never over-states the free space). A peer killed before publish() never sees the records.
  bool try_push_deferred(const Record& record) {
    if (error_ != RingError::kNone) return false;
    if (write_pos_ - seen_read_ >= capacity_) {
      // acquire: pairs with the consumer's release-store of read_pos, as in try_push().
      const uint64_t read = control_->read_pos.v.load(std::memory_order_acquire);
      if (read > write_pos_ || write_pos_ - read > capacity_ || read < seen_read_) {
        error_ = RingError::kPeerCorrupt;
        return false;
      }
      seen_read_ = read;
      if (write_pos_ - read == capacity_) return false;
    }
    copy_record(record);
    ++write_pos_;
    deferred_ = true;
    return true;
  }

  // Producer thread only: makes every record pushed with try_push_deferred() visible to the consumer.
  void publish() {
    if (!deferred_) return;
    deferred_ = false;
    // release: pairs with the consumer's acquire-load of write_pos; publishes the records copied before.
    control_->write_pos.v.store(write_pos_, std::memory_order_release);
  }

  // Producer thread only: records pushed with try_push_deferred() and not published yet (possibly already
  // published by a try_push() since; publish() is then a harmless repeat).
  bool has_deferred() const { return deferred_; }

  // Producer thread only: free space as seen now.
  uint32_t free_space() const {
    const uint64_t read = control_->read_pos.v.load(std::memory_order_acquire);  // pairs with consumer's release
    if (read > write_pos_ || write_pos_ - read > capacity_) return 0;
    return static_cast<uint32_t>(capacity_ - (write_pos_ - read));
  }

  // Producer thread only: the consumer's published read position, or nullopt when it is impossible (the
  // ring itself notices that only when it pushes, and a ring that looks full never pushes).
  std::optional<uint64_t> consumer_position() const {
    const uint64_t read = control_->read_pos.v.load(std::memory_order_acquire);  // pairs with consumer's release
    if (read > write_pos_ || write_pos_ - read > capacity_) return std::nullopt;
    return read;
  }

  RingError error() const { return error_; }
  uint64_t position() const { return write_pos_; }
  uint32_t capacity() const { return capacity_; }

  // Fault injection only: called in the middle of every push, with half of the record copied into the ring
  // and the write position not yet published (texstream-chaos's mid_ring_push kill point). nullptr: none.
  void set_mid_push_hook(void (*hook)()) { mid_push_hook_ = hook; }

 private:
  // Copies `record` into the place at write_pos_ (not yet published). Under fault injection the mid-push
  // hook runs with half of it copied: killed there, the torn record is never published.
  void copy_record(const Record& record) {
    auto* dst = reinterpret_cast<unsigned char*>(&records_[write_pos_ & (capacity_ - 1)]);
    if (mid_push_hook_ == nullptr) {
      std::memcpy(dst, &record, sizeof(Record));
      return;
    }
    constexpr size_t kHalf = sizeof(Record) / 2;
    std::memcpy(dst, &record, kHalf);
    mid_push_hook_();
    std::memcpy(dst + kHalf, reinterpret_cast<const unsigned char*>(&record) + kHalf, sizeof(Record) - kHalf);
  }

  RingControl* control_ = nullptr;
  Record* records_ = nullptr;
  uint32_t capacity_ = 0;
  uint64_t write_pos_ = 0;
  RingError error_ = RingError::kNone;
  void (*mid_push_hook_)() = nullptr;
  uint64_t seen_read_ = 0;  // try_push_deferred(): the consumer's read position when last loaded (≤ the truth)
  bool deferred_ = false;   // try_push_deferred() wrote records that publish() has not published
};

template <class Record>
class SpscRingConsumer {
  static_assert(std::is_trivially_copyable_v<Record>);

 public:
  SpscRingConsumer() = default;
  SpscRingConsumer(RingControl* control, Record* records, uint32_t capacity)
      : control_(control), records_(records), capacity_(capacity) {
    TS_ASSERT(capacity != 0 && (capacity & (capacity - 1)) == 0, "ring capacity %u is not a power of two", capacity);
    read_pos_ = control_->read_pos.v.load(std::memory_order_relaxed);  // relaxed: we are its only writer
  }

  // Consumer thread only. Copies the next record out of the segment (read once; the caller validates the
  // copy) or returns nullopt when empty or when the producer's published position is impossible.
  std::optional<Record> try_pop() {
    if (error_ != RingError::kNone) return std::nullopt;
    // acquire: pairs with the producer's release-store of write_pos; makes the record's bytes visible.
    const uint64_t write = control_->write_pos.v.load(std::memory_order_acquire);
    if (write < read_pos_ || write - read_pos_ > capacity_) {
      error_ = RingError::kPeerCorrupt;
      return std::nullopt;
    }
    if (write == read_pos_) return std::nullopt;
    Record out;
    std::memcpy(&out, &records_[read_pos_ & (capacity_ - 1)], sizeof(Record));
    ++read_pos_;
    // release: pairs with the producer's acquire-load of read_pos; our copy above is complete before the
    // producer may overwrite this record.
    control_->read_pos.v.store(read_pos_, std::memory_order_release);
    return out;
  }

  // Consumer thread only. Like try_pop(), but the record's place is handed back to the producer only at
  // publish() (or a later try_pop(), which hands back everything before it): a consumer draining a burst
  // pays one release-store of read_pos per burst instead of one per record, and loads the producer's write
  // position only when the records it last saw are used up. Call publish() before waiting for the producer.
  std::optional<Record> try_pop_deferred() {
    if (error_ != RingError::kNone) return std::nullopt;
    if (seen_write_ <= read_pos_) {  // used up (or stale: try_pop() went past it, or never loaded)
      // acquire: pairs with the producer's release-store of write_pos; makes the records' bytes visible.
      const uint64_t write = control_->write_pos.v.load(std::memory_order_acquire);
      if (write < read_pos_ || write - read_pos_ > capacity_) {
        error_ = RingError::kPeerCorrupt;
        return std::nullopt;
      }
      seen_write_ = write;
      if (write == read_pos_) return std::nullopt;
      // The new records were written by the producer's core: ask for the first few at once, so that their
      // transfers overlap instead of each copy below waiting for its own (a hint: no effect on the contents).
      for (uint64_t p = read_pos_ + 1; p < std::min(write, read_pos_ + kPrefetchAhead); ++p) prefetch(p);
    }
    if (read_pos_ + kPrefetchAhead < seen_write_) prefetch(read_pos_ + kPrefetchAhead);
    Record out;
    std::memcpy(&out, &records_[read_pos_ & (capacity_ - 1)], sizeof(Record));
    ++read_pos_;
    deferred_ = true;
    return out;
  }

  // Consumer thread only: hands back the places of the records taken with try_pop_deferred().
  void publish() {
    if (!deferred_) return;
    deferred_ = false;
    // release: pairs with the producer's acquire-load of read_pos; our copies are complete before the
    // producer may overwrite those records.
    control_->read_pos.v.store(read_pos_, std::memory_order_release);
  }

  // Consumer thread only: records waiting now (0 on a corrupt peer position).
  uint32_t size() const {
    const uint64_t write = control_->write_pos.v.load(std::memory_order_acquire);  // pairs with producer's release
    if (write < read_pos_ || write - read_pos_ > capacity_) return 0;
    return static_cast<uint32_t>(write - read_pos_);
  }

  RingError error() const { return error_; }
  uint64_t position() const { return read_pos_; }

 private:
  // try_pop_deferred() keeps the records up to this many places ahead on their way into the CPU cache.
  static constexpr uint64_t kPrefetchAhead = 8;
  void prefetch(uint64_t pos) const { __builtin_prefetch(&records_[pos & (capacity_ - 1)], 0, 3); }

  RingControl* control_ = nullptr;
  Record* records_ = nullptr;
  uint32_t capacity_ = 0;
  uint64_t read_pos_ = 0;
  RingError error_ = RingError::kNone;
  uint64_t seen_write_ = 0;  // try_pop_deferred(): the producer's write position when last loaded
  bool deferred_ = false;    // try_pop_deferred() took records whose places publish() has not handed back
};

}  // namespace texstream
