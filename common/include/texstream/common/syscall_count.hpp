#pragma once
// Kernel crossings we make ourselves, counted where we make them (issue 29: on a paravirtualised guest one
// costs ~1.2 µs, on bare metal ~0.1 µs, so the statistics say how many a served mip or a frame takes).
// Each thread counts into the counter its role installed (SyscallAccount); threads that installed none count
// into the process's. What a library does behind our back (malloc's mmap, a decode helper's pipes, libcurl)
// is not counted: texstream-bench server checks the count against the kernel's where perf allows it.
#include <array>
#include <atomic>
#include <cstdint>
#include <string>

namespace texstream {

enum class Syscall : uint8_t {
  kOpen,       // open, openat
  kRead,       // pread, preadv
  kClose,      // close of a texture file
  kStat,       // fstat
  kFutexWait,  // a futex wait or a condition-variable wait that blocks
  kFutexWake,  // a futex wake (or a notify that wakes a blocked thread)
  kYield,      // sched_yield
  kPoll,       // poll (a pidfd's liveness)
  kIoUring,    // io_uring_enter (one per batch of submissions and completions)
  kCount,
};
const char* to_string(Syscall kind);

class SyscallCounter {
 public:
  // relaxed: statistics, read for reports; the threads of one role share a counter.
  void add(Syscall kind, uint64_t n = 1) { n_[static_cast<size_t>(kind)].fetch_add(n, std::memory_order_relaxed); }
  uint64_t of(Syscall kind) const { return n_[static_cast<size_t>(kind)].load(std::memory_order_relaxed); }
  uint64_t total() const;
  // "N (open a, read b, ...)": the kinds that occurred.
  std::string describe() const;

 private:
  std::array<std::atomic<uint64_t>, static_cast<size_t>(Syscall::kCount)> n_{};
};

// The counter the calling thread counts into.
SyscallCounter& thread_syscalls();
// The process's counter: threads that installed none.
SyscallCounter& process_syscalls();

inline void count_syscall(Syscall kind, uint64_t n = 1) { thread_syscalls().add(kind, n); }

// Installs `counter` for the calling thread for the scope (the server's dispatcher and workers count into
// the server's statistics, the renderer's frame thread into the process's).
class SyscallAccount {
 public:
  explicit SyscallAccount(SyscallCounter& counter);
  ~SyscallAccount();
  SyscallAccount(const SyscallAccount&) = delete;
  SyscallAccount& operator=(const SyscallAccount&) = delete;

 private:
  SyscallCounter* previous_;
};

}  // namespace texstream
