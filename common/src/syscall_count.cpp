#include "texstream/common/syscall_count.hpp"

namespace texstream {

namespace {
SyscallCounter g_process;
thread_local SyscallCounter* t_counter = nullptr;
}  // namespace

const char* to_string(Syscall kind) {
  switch (kind) {
    case Syscall::kOpen:
      return "open";
    case Syscall::kRead:
      return "read";
    case Syscall::kClose:
      return "close";
    case Syscall::kStat:
      return "stat";
    case Syscall::kFutexWait:
      return "futex wait";
    case Syscall::kFutexWake:
      return "futex wake";
    case Syscall::kYield:
      return "yield";
    case Syscall::kPoll:
      return "poll";
    case Syscall::kIoUring:
      return "io_uring_enter";
    case Syscall::kCount:
      break;
  }
  return "?";
}

uint64_t SyscallCounter::total() const {
  uint64_t sum = 0;
  for (const auto& n : n_) sum += n.load(std::memory_order_relaxed);
  return sum;
}

std::string SyscallCounter::describe() const {
  std::string out = std::to_string(total());
  std::string parts;
  for (size_t i = 0; i < n_.size(); ++i) {
    const uint64_t n = n_[i].load(std::memory_order_relaxed);
    if (n == 0) continue;
    parts += (parts.empty() ? "" : ", ") + std::string(to_string(static_cast<Syscall>(i))) + " " + std::to_string(n);
  }
  return parts.empty() ? out : out + " (" + parts + ")";
}

SyscallCounter& process_syscalls() { return g_process; }

SyscallCounter& thread_syscalls() { return t_counter != nullptr ? *t_counter : g_process; }

SyscallAccount::SyscallAccount(SyscallCounter& counter) : previous_(t_counter) { t_counter = &counter; }

SyscallAccount::~SyscallAccount() { t_counter = previous_; }

}  // namespace texstream
