#include "child_process.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <sstream>
#include <thread>

namespace texstream::chaos {

Result<ChildProcess> ChildProcess::spawn(const std::vector<std::string>& argv, const std::filesystem::path& log,
                                         const std::vector<std::string>& env) {
  SpawnOptions options;
  options.fds = {SpawnFd::open(1, log.string(), O_WRONLY | O_CREAT | O_APPEND, 0644), SpawnFd::dup2(1, 2)};
  options.extra_env = env;
  const Result<pid_t> pid = spawn_process(argv, options);
  if (!pid) return pid.error();
  return ChildProcess(*pid);
}

ChildProcess::~ChildProcess() {
  if (pid_ > 0) kill_and_wait_process(pid_);
}

std::optional<ExitStatus> ChildProcess::try_wait() {
  if (pid_ <= 0) return std::nullopt;
  std::optional<ExitStatus> e = try_wait_process(pid_);
  if (e) pid_ = -1;
  return e;
}

std::optional<ExitStatus> ChildProcess::wait_for(std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (true) {
    if (auto e = try_wait()) return e;
    if (std::chrono::steady_clock::now() >= end) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

std::optional<std::string> read_whole_file(const std::filesystem::path& file) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return std::nullopt;
  std::string out;
  char buf[65536];
  while (true) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      ::close(fd);
      return std::nullopt;
    }
    if (n == 0) break;
    out.append(buf, static_cast<size_t>(n));
  }
  ::close(fd);
  return out;
}

std::optional<ProcInfo> read_proc(pid_t pid) {
  const auto text = read_whole_file("/proc/" + std::to_string(pid) + "/stat");
  if (!text) return std::nullopt;
  const std::string& line = *text;
  // "pid (comm) state ppid ...": comm may hold spaces and parentheses, so split at the last ')'.
  const size_t open = line.find('(');
  const size_t close = line.rfind(')');
  if (open == std::string::npos || close == std::string::npos || close + 2 >= line.size()) return std::nullopt;
  ProcInfo p;
  p.pid = pid;
  p.comm = line.substr(open + 1, close - open - 1);
  std::istringstream rest(line.substr(close + 2));
  long ppid = 0;
  rest >> p.state >> ppid;
  p.ppid = static_cast<pid_t>(ppid);
  return p;
}

namespace {
template <class F>
void for_each_pid(F f) {
  DIR* d = ::opendir("/proc");
  if (!d) return;
  while (dirent* e = ::readdir(d)) {
    char* end = nullptr;
    const long pid = std::strtol(e->d_name, &end, 10);
    if (pid <= 0 || *end != '\0') continue;
    f(static_cast<pid_t>(pid));
  }
  ::closedir(d);
}
}  // namespace

std::vector<ProcInfo> children_of(pid_t parent) {
  std::vector<ProcInfo> out;
  for_each_pid([&](pid_t pid) {
    if (auto p = read_proc(pid); p && p->ppid == parent && p->state != 'Z') out.push_back(*p);
  });
  return out;
}

std::vector<pid_t> processes_with_arg(const std::string& needle) {
  std::vector<pid_t> out;
  for_each_pid([&](pid_t pid) {
    const std::string cmdline = read_whole_file("/proc/" + std::to_string(pid) + "/cmdline").value_or("");
    if (cmdline.find(needle) == std::string::npos) return;
    if (auto p = read_proc(pid); p && p->state != 'Z') out.push_back(pid);
  });
  return out;
}

}  // namespace texstream::chaos
