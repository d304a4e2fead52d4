#pragma once
// The renderer's end of the protocol over one segment: push loads (mips, pages) and slot releases into the request
// ring, ring the doorbell, take completions off the completion ring. StreamClient, the test harness
// (tests/integration/server_harness.hpp) and texstream-bench server all use this one copy.
//
// It trusts nothing it reads: poll() returns an untrusted copy of a completion for the caller to validate
// (completion_check.hpp). Slot ownership is the caller's: release() only carries a slot back to the server.
//
// Renderer process, one thread: the one that makes every call (the rings are single-producer, single-consumer).
#include <chrono>
#include <cstdint>
#include <deque>
#include <optional>
#include <thread>

#include "texstream/common/ids.hpp"
#include "texstream/protocol/doorbell.hpp"
#include "texstream/protocol/records.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/protocol/spsc_ring.hpp"

namespace texstream {

class RendererEndpoint {
 public:
  RendererEndpoint() = default;
  // Resumes from the rings' published positions: make a new endpoint after Segment::reset_after_server_death()
  // (the queued releases go with the old one: the next server owns every slot).
  explicit RendererEndpoint(Segment& segment)
      : requests_(segment.request_producer()),
        completions_(segment.completion_consumer()),
        doorbell_(Doorbell(segment)),
        bell_(CompletionBell(segment)) {}

  // Pushes a kLoad; false when the request ring is full (or broken: ring_broken()). Visible to the server at
  // once; the server is woken by the next ring().
  bool push_load(TextureId texture, MipLevel mip, Generation generation, float priority) {
    if (!requests_.try_push(make_load_request(texture, mip, generation, priority))) return false;
    pushed_ = true;
    return true;
  }

  // Pushes a kLoadPage of `page` of page file `file` (0 = the scene's ground), as push_load().
  bool push_load_page(uint32_t file, pages::PageId page, Generation generation, float priority) {
    if (!requests_.try_push(make_load_page_request(file, page, generation, priority))) return false;
    pushed_ = true;
    return true;
  }

  // Queues `slot` to go back to the server; flush_releases() pushes it.
  void release(SlotIndex slot) { releases_.push_back(slot); }
  // Pushes queued releases, oldest first, while the request ring has room, calling on_pushed(slot, position)
  // with each record's ring position (the slot is the server's once its read position has passed that).
  // Returns how many were pushed; the rest wait for the next call.
  template <class OnPushed>
  uint32_t flush_releases(Generation generation, OnPushed&& on_pushed) {
    uint32_t n = 0;
    while (!releases_.empty()) {
      const uint64_t position = requests_.position();
      if (!requests_.try_push(make_release_request(releases_.front(), generation))) break;
      on_pushed(releases_.front(), position);
      releases_.pop_front();
      pushed_ = true;
      ++n;
    }
    return n;
  }
  uint32_t flush_releases(Generation generation = Generation(0)) {
    return flush_releases(generation, [](SlotIndex, uint64_t) {});
  }
  size_t releases_queued() const { return releases_.size(); }
  void drop_releases() { releases_.clear(); }

  // Rings the doorbell if anything was pushed since the last ring (doorbell.hpp: the renderer's half).
  void ring() {
    if (!pushed_) return;
    pushed_ = false;
    doorbell_->ring();
  }

  // The next completion, an untrusted copy; nullopt when none waits or the server's position is impossible.
  std::optional<CompletionRecord> poll() { return completions_.try_pop(); }

  // Blocks at most `timeout` until the server publishes a completion (at once if one waits): for a caller
  // with nothing else to do. Costs no system call when one is already there; a server that publishes while
  // nobody waits makes none either (CompletionBell).
  void wait_for_completions(std::chrono::microseconds timeout) {
    if (!bell_) {
      std::this_thread::sleep_for(timeout);
      return;
    }
    bell_->sleep(timeout, [this] { return completions_.size() > 0 || completions_broken(); });
  }

  // Request-ring records free now (0 when the server's position is impossible).
  uint32_t request_free_space() const { return requests_.free_space(); }
  uint64_t request_position() const { return requests_.position(); }
  // The server's published read position of the request ring, or nullopt when it is impossible.
  std::optional<uint64_t> server_read_position() const { return requests_.consumer_position(); }
  // A ring saw an impossible position published by the server: nothing more moves through it.
  bool ring_broken() const { return requests_.error() != RingError::kNone || completions_.error() != RingError::kNone; }
  bool completions_broken() const { return completions_.error() != RingError::kNone; }

 private:
  SpscRingProducer<RequestRecord> requests_;
  SpscRingConsumer<CompletionRecord> completions_;
  std::optional<Doorbell> doorbell_;  // empty only in a default-constructed endpoint
  std::optional<CompletionBell> bell_;
  std::deque<SlotIndex> releases_;
  bool pushed_ = false;  // a record pushed since the last ring()
};

}  // namespace texstream
