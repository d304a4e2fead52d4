#include "texstream/protocol/liveness.hpp"

#include <linux/futex.h>
#include <poll.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <fstream>
#include <sstream>
#include <string>

#include "texstream/common/syscall_count.hpp"

namespace texstream {

namespace {
// Fields of /proc/<pid>/stat after the command name (which may contain spaces and parentheses).
bool read_stat(int pid, char* state, uint64_t* start_time) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/stat");
  if (!f) return false;
  std::string line;
  std::getline(f, line);
  const auto close = line.rfind(')');
  if (close == std::string::npos) return false;
  std::istringstream rest(line.substr(close + 2));
  std::string field;
  // Field 3 is the state; field 22 is starttime. After ')' we are at field 3.
  for (int i = 3; i <= 22; ++i) {
    if (!(rest >> field)) return false;
    if (i == 3) *state = field[0];
    if (i == 22) *start_time = std::stoull(field);
  }
  return true;
}
}  // namespace

std::optional<uint64_t> process_start_time(int pid) {
  char state = 0;
  uint64_t start = 0;
  if (pid <= 0 || !read_stat(pid, &state, &start)) return std::nullopt;
  return start;
}

bool process_alive(int pid, uint64_t start_time) {
  char state = 0;
  uint64_t start = 0;
  if (pid <= 0 || !read_stat(pid, &state, &start)) return false;
  return start == start_time && state != 'Z' && state != 'X';
}

bool process_stopped(int pid) {
  char state = 0;
  uint64_t start = 0;
  return pid > 0 && read_stat(pid, &state, &start) && (state == 'T' || state == 't');
}

PidWatch::PidWatch(int pid) { fd_ = static_cast<int>(syscall(SYS_pidfd_open, pid, 0)); }

PidWatch::~PidWatch() {
  if (fd_ >= 0) ::close(fd_);
}

PidWatch::PidWatch(PidWatch&& o) noexcept : fd_(o.fd_) { o.fd_ = -1; }

PidWatch& PidWatch::operator=(PidWatch&& o) noexcept {
  if (this != &o) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = o.fd_;
    o.fd_ = -1;
  }
  return *this;
}

bool PidWatch::dead() const {
  if (fd_ < 0) return true;
  pollfd p{fd_, POLLIN, 0};
  count_syscall(Syscall::kPoll);
  const int r = ::poll(&p, 1, 0);
  return r > 0 && (p.revents & (POLLIN | POLLHUP | POLLERR)) != 0;
}

void futex_wake_all(ShmAtomic<uint32_t>& word) {
  count_syscall(Syscall::kFutexWake);
  syscall(SYS_futex, reinterpret_cast<uint32_t*>(&word.v), FUTEX_WAKE, INT_MAX, nullptr, nullptr, 0);
}

void futex_wait(ShmAtomic<uint32_t>& word, uint32_t expected, std::chrono::microseconds timeout) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(timeout.count() / 1000000);
  ts.tv_nsec = static_cast<long>((timeout.count() % 1000000) * 1000);
  count_syscall(Syscall::kFutexWait);
  syscall(SYS_futex, reinterpret_cast<uint32_t*>(&word.v), FUTEX_WAIT, expected, &ts, nullptr, 0);
}

}  // namespace texstream
