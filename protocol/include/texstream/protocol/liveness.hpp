#pragma once
// Process identity and death, told by the kernel: a pid is reused, so identity is (pid, start time from
// /proc/<pid>/stat); death is a pidfd becoming readable. Waking an idle server uses a futex on a shared word.
#include <chrono>
#include <cstdint>
#include <optional>

#include "texstream/protocol/shm_atomic.hpp"

namespace texstream {

// Start time of `pid` in clock ticks since boot, or nullopt if no such process.
std::optional<uint64_t> process_start_time(int pid);
// True if a process with this pid exists and started at `start_time` (and is not a zombie).
bool process_alive(int pid, uint64_t start_time);
// True if the process is stopped by a signal (SIGSTOP, SIGTSTP) or a tracer: state T or t in /proc/<pid>/stat.
bool process_stopped(int pid);

// Owns a pidfd. `dead()` polls it without blocking: true once the process has exited.
class PidWatch {
 public:
  PidWatch() = default;
  explicit PidWatch(int pid);
  ~PidWatch();
  PidWatch(PidWatch&& o) noexcept;
  PidWatch& operator=(PidWatch&& o) noexcept;
  PidWatch(const PidWatch&) = delete;
  PidWatch& operator=(const PidWatch&) = delete;

  bool valid() const { return fd_ >= 0; }
  bool dead() const;
  int fd() const { return fd_; }

 private:
  int fd_ = -1;
};

// Futex on a 32-bit word in the shared segment (not FUTEX_PRIVATE: the word is shared between processes).
void futex_wake_all(ShmAtomic<uint32_t>& word);
// Waits while `word == expected`, at most `timeout`. Returns on wake, timeout, signal or value change.
void futex_wait(ShmAtomic<uint32_t>& word, uint32_t expected, std::chrono::microseconds timeout);

}  // namespace texstream
