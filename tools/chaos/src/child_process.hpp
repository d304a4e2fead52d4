#pragma once
// Processes the chaos tool starts and watches: spawn with output to a log file, wait with a deadline, and
// find a process's children by scanning /proc (the renderer's texstream-server is its child; its pid
// changes at every restart). Linux only.
#include <sys/types.h>

#include <chrono>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "texstream/common/child_process.hpp"
#include "texstream/common/result.hpp"

namespace texstream::chaos {

using texstream::ExitStatus;

class ChildProcess {
 public:
  // argv[0] is the executable path. stdout and stderr go to `log` (appended). `env` adds NAME=VALUE entries.
  static Result<ChildProcess> spawn(const std::vector<std::string>& argv, const std::filesystem::path& log,
                                    const std::vector<std::string>& env = {});
  ChildProcess(ChildProcess&& o) noexcept : pid_(o.pid_) { o.pid_ = -1; }
  ChildProcess& operator=(ChildProcess&&) = delete;
  ChildProcess(const ChildProcess&) = delete;
  ~ChildProcess();  // kills and reaps a child still running

  pid_t pid() const { return pid_; }
  std::optional<ExitStatus> try_wait();  // non-blocking
  // Waits until the child exits or the timeout passes (nullopt: still running).
  std::optional<ExitStatus> wait_for(std::chrono::milliseconds timeout);

 private:
  explicit ChildProcess(pid_t pid) : pid_(pid) {}
  pid_t pid_ = -1;
};

struct ProcInfo {
  pid_t pid = 0;
  pid_t ppid = 0;
  char state = '?';  // R, S, T (stopped), Z ...
  std::string comm;  // at most 15 characters (TASK_COMM_LEN)
};
std::optional<ProcInfo> read_proc(pid_t pid);
// The whole file (small files: /proc entries, texture files); nullopt if it cannot be read.
std::optional<std::string> read_whole_file(const std::filesystem::path& file);
std::vector<ProcInfo> children_of(pid_t parent);
// Pids whose command line contains `needle` (e.g. a segment name), excluding zombies.
std::vector<pid_t> processes_with_arg(const std::string& needle);

}  // namespace texstream::chaos
