#pragma once
// Child processes, started one way everywhere (the renderer's texture server, the server's decode helper,
// the chaos tool's renderers, the path bench's runs): posix_spawn with argv, extra environment entries,
// descriptor actions applied in order in the child, and optionally a clean signal state; then wait or kill.
// Linux only (posix_spawn_file_actions_addclosefrom_np needs glibc >= 2.34).
#include <sys/types.h>

#include <optional>
#include <string>
#include <vector>

#include "texstream/common/result.hpp"

namespace texstream {

// One descriptor action, done in the child before exec, in the order given.
struct SpawnFd {
  enum class Kind { kOpen, kDup2, kCloseFrom };
  Kind kind = Kind::kOpen;
  int fd = -1;       // kOpen/kDup2: the child's descriptor; kCloseFrom: the first one closed
  int from = -1;     // kDup2: the parent's descriptor copied to `fd`
  std::string path;  // kOpen
  int flags = 0;     // kOpen
  mode_t mode = 0;   // kOpen

  static SpawnFd open(int fd, std::string path, int flags, mode_t mode = 0644);
  static SpawnFd dup2(int from, int to);
  static SpawnFd close_from(int first);
};

// The child's signal state. kInherit keeps the parent's mask and ignored signals (exec resets handlers).
// kReset: an empty mask and default dispositions for `defaults` (all signals when empty): a parent that
// blocks or ignores signals on some thread must not hand that to a child that should die of SIGTERM/SIGPIPE.
struct SpawnSignals {
  bool reset = false;
  std::vector<int> defaults;  // empty with reset: every signal
};

struct SpawnOptions {
  std::vector<SpawnFd> fds;
  std::vector<std::string> extra_env;  // NAME=VALUE, after this process's environment
  SpawnSignals signals;
};

// Starts argv[0] (a path, not searched in PATH) with `argv`. Error kIo names argv[0] and posix_spawn's error.
Result<pid_t> spawn_process(const std::vector<std::string>& argv, const SpawnOptions& options = {});

struct ExitStatus {
  bool exited = false;  // normal exit (code), else killed by `signal`
  int code = 0;
  int signal = 0;
  int raw = 0;  // the wait status as waitpid gave it
  static ExitStatus from_wait_status(int status);
  std::string describe() const;  // "exited with status N" / "killed by signal N (name)"
};

// Blocks until `pid` ends and reaps it (EINTR retried); nullopt if it cannot be waited for (ECHILD: not our
// child, or already reaped).
std::optional<ExitStatus> wait_process(pid_t pid);
// Reaps `pid` if it has ended; nullopt while it runs (or if it cannot be waited for).
std::optional<ExitStatus> try_wait_process(pid_t pid);
// SIGKILL, then wait_process.
std::optional<ExitStatus> kill_and_wait_process(pid_t pid);

}  // namespace texstream
