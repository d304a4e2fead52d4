#pragma once
// The doorbell: how the renderer wakes a server that went to sleep because it had nothing to do. Both halves
// of the handshake and their orders live here, so there is one memory-order story for both processes.
//
// Words (segment_layout.hpp): RendererBlock::doorbell, a futex word only the renderer writes (bumped after
// pushing requests); ServerBlock::sleeping, only the server writes (1 while its dispatcher waits on the word).
//
// The handshake is Dekker's: each side stores its own word, then loads the other's. All four are seq_cst: a
// store followed by a load of another word is the one pair no weaker order keeps in order, and operations
// rather than fences so that TSan sees them.
//   renderer ring():  (push records: ring release) ; A: doorbell += 1 ; B: load sleeping ; == 1 → FUTEX_WAKE
//   server sleep():   C: sleeping = 1 ; D: seen = load doorbell ; no work → FUTEX_WAIT(doorbell, seen) ; 0
// In the single order of A, B, C, D: if B misses C, then B < C, so A < D and D sees the bump, and through it
// (A releases, D acquires) the records pushed before it: the server's re-check finds them. If D misses A,
// FUTEX_WAIT finds the word changed and returns at once. Either way no pushed record waits for a timeout.
#include <chrono>
#include <cstdint>

#include "texstream/protocol/liveness.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/protocol/segment_layout.hpp"

namespace texstream {

// Two pointers into the segment: cheap to copy (the server's load workers keep one each).
class Doorbell {
 public:
  explicit Doorbell(Segment& segment) : Doorbell(segment.renderer_block(), segment.server_block()) {}
  Doorbell(RendererBlock& renderer, ServerBlock& server) : word_(&renderer.doorbell), sleeping_(&server.sleeping) {}

  // Renderer process, the thread that pushes requests, after its pushes: the renderer's half (A, B).
  void ring() {
    // seq_cst (A): pairs with the server's seq_cst load of the word (D); its release half publishes the
    // records pushed before to a server that sees the bump.
    word_->v.fetch_add(1, std::memory_order_seq_cst);
    // seq_cst (B): pairs with the server's seq_cst store of sleeping = 1 (C); see the order story above.
    if (sleeping_->v.load(std::memory_order_seq_cst) == 1) futex_wake_all(*word_);
  }

  // Server process, dispatcher thread only: the server's half (C, D). Sleeps at most `timeout` on the word,
  // unless `has_work()`, asked after `sleeping` is published, finds something to do. Returns on a ring, a
  // wake_sleeper(), a signal or the timeout.
  template <class HasWork>
  void sleep(std::chrono::microseconds timeout, HasWork&& has_work) {
    // seq_cst (C): pairs with the renderer's seq_cst load of sleeping (B), and with the load in wake_sleeper().
    sleeping_->v.store(1, std::memory_order_seq_cst);
    // seq_cst (D): pairs with the renderer's seq_cst bump (A).
    const uint32_t seen = word_->v.load(std::memory_order_seq_cst);
    if (!has_work()) futex_wait(*word_, seen, timeout);
    // relaxed: a 0 seen late costs the renderer one needless FUTEX_WAKE, nothing more.
    sleeping_->v.store(0, std::memory_order_relaxed);
  }

  // Server process, any thread (a load worker that published a result): wakes the dispatcher if it sleeps.
  // The caller published its result with a seq_cst store before; the dispatcher looks at it in has_work()
  // after its seq_cst store of sleeping: one of the two sees the other. FUTEX_WAKE does not write the word:
  // the renderer stays its only writer.
  void wake_sleeper() const {
    // seq_cst: pairs with the dispatcher's seq_cst store of sleeping = 1 (C).
    if (sleeping_->v.load(std::memory_order_seq_cst) == 1) futex_wake_all(*word_);
  }

  // Either process, any thread: wakes whoever waits on the word without bumping it (an in-process server
  // asked to stop through its flag; it re-checks the flag on waking).
  void wake_all() const { futex_wake_all(*word_); }

 private:
  ShmAtomic<uint32_t>* word_;
  ShmAtomic<uint32_t>* sleeping_;
};

// The completion bell: the same handshake the other way round, for a renderer thread that has nothing to do
// until completions arrive (a lock-step frame, a preload, texstream-bench server's client). Words:
// ServerBlock::completion_bell, only the server writes (bumped after publishing completions);
// RendererBlock::waiting, only the renderer writes (1 while it waits on the bell). A server that publishes
// while nobody waits makes no system call (issue 29: no per-record wake, no yield loop).
//   server ring():    (publish completions: ring release) ; A: bell += 1 ; B: load waiting ; == 1 → FUTEX_WAKE
//   renderer wait():  C: waiting = 1 ; D: seen = load bell ; nothing to take → FUTEX_WAIT(bell, seen) ; 0
// The argument is the doorbell's, with the roles swapped.
class CompletionBell {
 public:
  explicit CompletionBell(Segment& segment) : CompletionBell(segment.renderer_block(), segment.server_block()) {}
  CompletionBell(RendererBlock& renderer, ServerBlock& server)
      : word_(&server.completion_bell), waiting_(&renderer.waiting) {}

  // Server process, dispatcher thread, after publishing completions: the server's half (A, B).
  void ring() {
    // seq_cst (A): pairs with the renderer's seq_cst load of the word (D); releases the published records.
    word_->v.fetch_add(1, std::memory_order_seq_cst);
    // seq_cst (B): pairs with the renderer's seq_cst store of waiting = 1 (C).
    if (waiting_->v.load(std::memory_order_seq_cst) == 1) futex_wake_all(*word_);
  }

  // Renderer process, the thread that polls: waits at most `timeout` unless `has_work()`, asked after
  // `waiting` is published, finds a completion (the renderer's half, C and D).
  template <class HasWork>
  void wait(std::chrono::microseconds timeout, HasWork&& has_work) {
    // seq_cst (C): pairs with the server's seq_cst load of waiting (B).
    waiting_->v.store(1, std::memory_order_seq_cst);
    // seq_cst (D): pairs with the server's seq_cst bump (A).
    const uint32_t seen = word_->v.load(std::memory_order_seq_cst);
    if (!has_work()) futex_wait(*word_, seen, timeout);
    // relaxed: a 1 seen late costs the server one needless FUTEX_WAKE, nothing more.
    waiting_->v.store(0, std::memory_order_relaxed);
  }

 private:
  ShmAtomic<uint32_t>* word_;
  ShmAtomic<uint32_t>* waiting_;
};

}  // namespace texstream
