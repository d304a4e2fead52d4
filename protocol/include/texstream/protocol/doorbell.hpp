#pragma once
// The two bells between the processes, one mechanism (Bell): a side that has nothing to do says it is about
// to sleep, and the other makes a system call only then (issue 29: no per-record wake, no yield loop).
//   Doorbell: the renderer wakes a server that went to sleep because it had nothing to do.
//   CompletionBell: the server wakes a renderer thread that waits for completions (a lock-step frame, a
//   preload, texstream-bench server's client).
// Both halves of each handshake and their orders live here: one memory-order story for both processes.
//
// Words (segment_layout.hpp): the futex word only the ringing side writes (bumped after publishing records:
// RendererBlock::doorbell, ServerBlock::completion_bell) and the flag only the sleeping side writes (1 while
// it waits on the word: ServerBlock::sleeping, RendererBlock::waiting).
//
// The handshake is Dekker's: each side stores its own word, then loads the other's. All four are seq_cst: a
// store followed by a load of another word is the one pair no weaker order keeps in order, and operations
// rather than fences so that TSan sees them.
//   ring():   (publish records: ring release) ; A: word += 1 ; B: load flag ; == 1 → FUTEX_WAKE
//   sleep():  C: flag = 1 ; D: seen = load word ; no work → FUTEX_WAIT(word, seen) ; flag = 0
// In the single order of A, B, C, D: if B misses C, then B < C, so A < D and D sees the bump, and through it
// (A releases, D acquires) the records published before it: the sleeper's re-check finds them. If D misses A,
// FUTEX_WAIT finds the word changed and returns at once. Either way no record waits for a timeout.
#include <chrono>
#include <cstdint>

#include "texstream/protocol/liveness.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/protocol/segment_layout.hpp"

namespace texstream {

// Two pointers into the segment: cheap to copy (the server's load workers keep one each).
class Bell {
 public:
  Bell(ShmAtomic<uint32_t>& word, ShmAtomic<uint32_t>& flag) : word_(&word), flag_(&flag) {}

  // The ringing side, after publishing its records (A, B).
  void ring() {
    // seq_cst (A): pairs with the sleeper's seq_cst load of the word (D); its release half publishes the
    // records published before to a sleeper that sees the bump.
    word_->v.fetch_add(1, std::memory_order_seq_cst);
    // seq_cst (B): pairs with the sleeper's seq_cst store of flag = 1 (C).
    if (flag_->v.load(std::memory_order_seq_cst) == 1) futex_wake_all(*word_);
  }

  // The sleeping side, its one waiting thread: sleeps at most `timeout` on the word, unless `has_work()`,
  // asked after the flag is published, finds something to do (C, D). Returns on a ring, a wake_sleeper(), a
  // signal or the timeout.
  template <class HasWork>
  void sleep(std::chrono::microseconds timeout, HasWork&& has_work) {
    // seq_cst (C): pairs with the ringer's seq_cst load of the flag (B), and with the load in wake_sleeper().
    flag_->v.store(1, std::memory_order_seq_cst);
    // seq_cst (D): pairs with the ringer's seq_cst bump (A).
    const uint32_t seen = word_->v.load(std::memory_order_seq_cst);
    if (!has_work()) futex_wait(*word_, seen, timeout);
    // relaxed: a 1 seen late costs the ringer one needless FUTEX_WAKE, nothing more.
    flag_->v.store(0, std::memory_order_relaxed);
  }

  // Any thread of the sleeping side's process that published a result the sleeper looks at in has_work() (a
  // server's load worker): wakes the sleeper if it sleeps. The caller published its result with a seq_cst
  // store before; the sleeper looks at it after its seq_cst store of the flag: one of the two sees the other.
  // FUTEX_WAKE does not write the word: the ringing side stays its only writer.
  void wake_sleeper() const {
    // seq_cst: pairs with the sleeper's seq_cst store of flag = 1 (C).
    if (flag_->v.load(std::memory_order_seq_cst) == 1) futex_wake_all(*word_);
  }

  // Either process, any thread: wakes whoever waits on the word without bumping it (an in-process server
  // asked to stop through its flag; it re-checks the flag on waking).
  void wake_all() const { futex_wake_all(*word_); }

 private:
  ShmAtomic<uint32_t>* word_;
  ShmAtomic<uint32_t>* flag_;
};

// The renderer rings after pushing requests; the server's dispatcher sleeps on it.
class Doorbell : public Bell {
 public:
  explicit Doorbell(Segment& segment) : Doorbell(segment.renderer_block(), segment.server_block()) {}
  Doorbell(RendererBlock& renderer, ServerBlock& server) : Bell(renderer.doorbell, server.sleeping) {}
};

// The server rings after publishing completions; a renderer thread with nothing else to do waits on it.
class CompletionBell : public Bell {
 public:
  explicit CompletionBell(Segment& segment) : CompletionBell(segment.renderer_block(), segment.server_block()) {}
  CompletionBell(RendererBlock& renderer, ServerBlock& server) : Bell(server.completion_bell, renderer.waiting) {}
};

}  // namespace texstream
