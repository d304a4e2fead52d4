#include "texstream/common/child_process.hpp"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>

#include <cerrno>
#include <cstring>

extern char** environ;

namespace texstream {

SpawnFd SpawnFd::open(int fd, std::string path, int flags, mode_t mode) {
  SpawnFd a;
  a.kind = Kind::kOpen;
  a.fd = fd;
  a.path = std::move(path);
  a.flags = flags;
  a.mode = mode;
  return a;
}

SpawnFd SpawnFd::dup2(int from, int to) {
  SpawnFd a;
  a.kind = Kind::kDup2;
  a.fd = to;
  a.from = from;
  return a;
}

SpawnFd SpawnFd::close_from(int first) {
  SpawnFd a;
  a.kind = Kind::kCloseFrom;
  a.fd = first;
  return a;
}

namespace {

// The posix_spawn attribute and file-action objects for one spawn, destroyed with it.
class SpawnState {
 public:
  explicit SpawnState(const SpawnOptions& o) {
    posix_spawnattr_init(&attr_);
    posix_spawn_file_actions_init(&actions_);
    if (o.signals.reset) {
      sigset_t none;
      sigemptyset(&none);
      posix_spawnattr_setsigmask(&attr_, &none);
      sigset_t defaults;
      if (o.signals.defaults.empty()) {
        sigfillset(&defaults);
      } else {
        sigemptyset(&defaults);
        for (int sig : o.signals.defaults) sigaddset(&defaults, sig);
      }
      posix_spawnattr_setsigdefault(&attr_, &defaults);
      posix_spawnattr_setflags(&attr_, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
    }
    for (const SpawnFd& f : o.fds) {
      switch (f.kind) {
        case SpawnFd::Kind::kOpen:
          posix_spawn_file_actions_addopen(&actions_, f.fd, f.path.c_str(), f.flags, f.mode);
          break;
        case SpawnFd::Kind::kDup2:
          posix_spawn_file_actions_adddup2(&actions_, f.from, f.fd);
          break;
        case SpawnFd::Kind::kCloseFrom:
          posix_spawn_file_actions_addclosefrom_np(&actions_, f.fd);
          break;
      }
    }
  }
  ~SpawnState() {
    posix_spawn_file_actions_destroy(&actions_);
    posix_spawnattr_destroy(&attr_);
  }
  SpawnState(const SpawnState&) = delete;
  SpawnState& operator=(const SpawnState&) = delete;
  const posix_spawnattr_t* attr() const { return &attr_; }
  const posix_spawn_file_actions_t* actions() const { return &actions_; }

 private:
  posix_spawnattr_t attr_{};
  posix_spawn_file_actions_t actions_{};
};

std::vector<char*> c_strings(const std::vector<std::string>& v) {
  std::vector<char*> out;
  out.reserve(v.size() + 1);
  for (const std::string& s : v) out.push_back(const_cast<char*>(s.c_str()));  // posix_spawn's signature
  out.push_back(nullptr);
  return out;
}

std::optional<ExitStatus> wait_with(pid_t pid, int options) {
  int status = 0;
  pid_t r;
  do {
    r = ::waitpid(pid, &status, options);
  } while (r < 0 && errno == EINTR);
  if (r != pid) return std::nullopt;
  return ExitStatus::from_wait_status(status);
}

}  // namespace

Result<pid_t> spawn_process(const std::vector<std::string>& argv, const SpawnOptions& options) {
  if (argv.empty()) return make_error(ErrorCode::kInvalidArgument, "spawn_process: empty argv");
  std::vector<char*> args = c_strings(argv);
  std::vector<char*> envp;
  std::vector<std::string> env_strings;
  char** env = environ;
  if (!options.extra_env.empty()) {
    for (char** e = environ; *e; ++e) env_strings.emplace_back(*e);
    env_strings.insert(env_strings.end(), options.extra_env.begin(), options.extra_env.end());
    envp = c_strings(env_strings);
    env = envp.data();
  }
  pid_t pid = -1;
  int err;
  {
    const SpawnState state(options);
    err = ::posix_spawn(&pid, args[0], state.actions(), state.attr(), args.data(), env);
  }
  if (err != 0) return make_error(ErrorCode::kIo, "cannot start '" + argv[0] + "': " + std::strerror(err));
  return pid;
}

ExitStatus ExitStatus::from_wait_status(int status) {
  ExitStatus e;
  e.raw = status;
  if (WIFEXITED(status)) {
    e.exited = true;
    e.code = WEXITSTATUS(status);
  } else if (WIFSIGNALED(status)) {
    e.signal = WTERMSIG(status);
  }
  return e;
}

std::string ExitStatus::describe() const {
  if (exited) return "exited with status " + std::to_string(code);
  if (signal != 0) return "killed by signal " + std::to_string(signal) + " (" + strsignal(signal) + ")";
  return "ended with wait status " + std::to_string(raw);
}

std::optional<ExitStatus> wait_process(pid_t pid) { return wait_with(pid, 0); }

std::optional<ExitStatus> try_wait_process(pid_t pid) { return wait_with(pid, WNOHANG); }

std::optional<ExitStatus> kill_and_wait_process(pid_t pid) {
  ::kill(pid, SIGKILL);
  return wait_process(pid);
}

}  // namespace texstream
