#include "texstream/render/server_process.hpp"

#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <spdlog/spdlog.h>
#include <system_error>
#include <utility>

extern char** environ;

namespace texstream {

namespace {

std::string describe_status(int status) {
  if (WIFEXITED(status)) return "exited with status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    return "killed by signal " + std::to_string(sig) + " (" + strsignal(sig) + ")";
  }
  return "ended with wait status " + std::to_string(status);
}

// posix_spawn attributes: the child starts with no blocked signals and default dispositions for the
// signals a renderer may ignore or catch, so `--spawned` servers die of SIGTERM/SIGPIPE as expected.
struct SpawnAttr {
  posix_spawnattr_t attr{};
  posix_spawn_file_actions_t actions{};
  SpawnAttr() {
    posix_spawnattr_init(&attr);
    posix_spawn_file_actions_init(&actions);
    sigset_t none;
    sigemptyset(&none);
    posix_spawnattr_setsigmask(&attr, &none);
    sigset_t defaults;
    sigemptyset(&defaults);
    for (int sig : {SIGPIPE, SIGINT, SIGTERM, SIGHUP, SIGCHLD, SIGUSR1, SIGUSR2}) sigaddset(&defaults, sig);
    posix_spawnattr_setsigdefault(&attr, &defaults);
    posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
    // Close every descriptor past stdio in the child (glibc >= 2.34): our pidfds, the shared-memory fd and
    // the Vulkan driver's files must not leak into the server or keep them alive after we close them.
    posix_spawn_file_actions_addclosefrom_np(&actions, 3);
  }
  ~SpawnAttr() {
    posix_spawn_file_actions_destroy(&actions);
    posix_spawnattr_destroy(&attr);
  }
  SpawnAttr(const SpawnAttr&) = delete;
  SpawnAttr& operator=(const SpawnAttr&) = delete;
};

}  // namespace

std::vector<std::string> ServerCommand::argv() const {
  std::vector<std::string> a{executable.string(), "--segment", segment_name, "--scene", scene_dir.string()};
  if (!config_file.empty()) {
    a.push_back("--config");
    a.push_back(config_file.string());
  }
  for (const std::string& o : overrides) {
    a.push_back("--set");
    a.push_back(o);
  }
  a.push_back("--spawned");
  return a;
}

Result<std::filesystem::path> resolve_server_executable(const Config& config) {
  std::filesystem::path exe;
  std::string source;
  if (!config.server.executable.empty()) {
    exe = config.server.executable;
    source = "config key 'server.executable'";
  } else {
    std::error_code ec;
    const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
    if (ec) return make_error(ErrorCode::kIo, "cannot read /proc/self/exe to find texstream-server: " + ec.message());
    exe = self.parent_path() / "texstream-server";
    source = "texstream-server next to " + self.string() + " (config key 'server.executable' is empty)";
  }
  if (::access(exe.c_str(), X_OK) != 0) {
    return make_error(ErrorCode::kNotFound,
                      "server executable '" + exe.string() + "' (" + source + "): " + std::strerror(errno));
  }
  return exe;
}

const char* to_string(ServerState state) {
  switch (state) {
    case ServerState::kStopped: return "stopped";
    case ServerState::kRunning: return "running";
    case ServerState::kBackingOff: return "backing off";
    case ServerState::kColormapOnly: return "colormap only";
  }
  return "?";
}

ServerProcess::ServerProcess(ServerCommand command, RestartPolicy policy)
    : command_(std::move(command)), policy_(policy) {}

ServerProcess::~ServerProcess() {
  if (pid_ <= 0) return;
  ::kill(pid_, SIGTERM);
  // Let it log its exit; a server that ignores SIGTERM for 500 ms is killed.
  constexpr int kTermGraceMs = 500;
  if (watch_.valid()) {
    pollfd p{watch_.fd(), POLLIN, 0};
    while (::poll(&p, 1, kTermGraceMs) < 0 && errno == EINTR) {
    }
  }
  ::kill(pid_, SIGKILL);
  int status = 0;
  while (::waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
  }
}

bool ServerProcess::spawn_if_due(SteadyTime now) {
  if (pid_ > 0 || spawn_failure_ || now < next_spawn_at_) return false;
  const std::vector<std::string> args = command_.argv();
  std::vector<char*> argv;
  argv.reserve(args.size() + 1);
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));  // posix_spawn's signature
  argv.push_back(nullptr);
  SpawnAttr sa;
  pid_t pid = -1;
  const int err = posix_spawn(&pid, argv[0], &sa.actions, &sa.attr, argv.data(), environ);
  ++spawns_;
  spawned_at_ = now;
  last_progress_ = now;
  last_heartbeat_ = 0;
  attached_ = false;
  killing_ = false;
  kill_reason_.clear();
  if (err != 0) {
    spawn_failure_ = ServerExit{0, std::string("could not be spawned: ") + std::strerror(err), false, {}};
    spdlog::error("texstream-server '{}' could not be spawned: {}", command_.executable.string(), std::strerror(err));
    return false;
  }
  pid_ = pid;
  watch_ = PidWatch(pid);
  if (!watch_.valid()) {
    // pidfd_open needs Linux 5.3; without it we still notice death through waitpid(WNOHANG) in reap().
    spdlog::warn("pidfd_open({}) failed ({}); watching texstream-server with waitpid only", pid, std::strerror(errno));
  }
  spdlog::info("texstream-server started: pid {} segment '{}' (spawn #{})", pid, command_.segment_name, spawns_);
  return true;
}

std::optional<ServerExit> ServerProcess::reap(SteadyTime now) {
  if (spawn_failure_) {
    ServerExit e = std::move(*spawn_failure_);
    spawn_failure_.reset();
    record_death(now, true);
    return e;
  }
  if (pid_ <= 0) return std::nullopt;
  // The pidfd is the cheap "has it died" test; without one, waitpid(WNOHANG) answers alone.
  if (watch_.valid() && !watch_.dead()) {
    if (colormap_only_ && now - spawned_at_ >= policy_.crash_window) {
      colormap_only_ = false;
      spdlog::info("texstream-server pid {} has run for {} s: leaving colormap-only mode", pid_,
                   std::chrono::duration_cast<std::chrono::seconds>(policy_.crash_window).count());
    }
    return std::nullopt;
  }
  int status = 0;
  pid_t r;
  do {
    r = ::waitpid(pid_, &status, WNOHANG);
  } while (r < 0 && errno == EINTR);
  if (r == 0) return std::nullopt;  // pidfd said dead but the exit is not reapable yet: next call
  ServerExit e;
  e.pid = pid_;
  e.how = r < 0 ? std::string("vanished (waitpid: ") + std::strerror(errno) + ")" : describe_status(status);
  e.killed_by_us = killing_;
  e.kill_reason = kill_reason_;
  // SIGKILL that we did not send came from outside (OOM killer, an operator, texstream-chaos): the server did
  // nothing wrong. Anything else it ended by itself (exit, SIGSEGV, SIGABRT, ...) or we killed it: a crash.
  const bool outside_kill = r > 0 && WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL && !killing_;
  const bool crash = !outside_kill;
  pid_ = -1;
  watch_ = PidWatch();
  killing_ = false;
  kill_reason_.clear();
  attached_ = false;
  record_death(now, crash);
  return e;
}

void ServerProcess::record_death(SteadyTime now, bool crash) {
  ++deaths_total_;
  if (!crash) {
    // It had started and was working until something outside killed it: replace it at once.
    next_spawn_at_ = now + policy_.first_delay;
    return;
  }
  ++crashes_total_;
  recent_deaths_.push_back(now);
  while (!recent_deaths_.empty() && now - recent_deaths_.front() > policy_.crash_window) recent_deaths_.pop_front();
  const size_t n = recent_deaths_.size();
  if (n >= policy_.crash_limit && !colormap_only_) {
    colormap_only_ = true;
    spdlog::error("texstream-server died {} times within {} s: colormap only, retrying every {} s", n,
                  std::chrono::duration_cast<std::chrono::seconds>(policy_.crash_window).count(),
                  std::chrono::duration_cast<std::chrono::seconds>(policy_.slow_retry).count());
  }
  if (colormap_only_) {
    next_spawn_at_ = now + policy_.slow_retry;
    return;
  }
  // first_delay · 2^(n-1), capped: crashes age out of the window, so the delay falls back by itself.
  auto delay = policy_.first_delay;
  for (size_t i = 1; i < n && delay < policy_.max_delay; ++i) delay *= 2;
  next_spawn_at_ = now + std::min(delay, policy_.max_delay);
}

bool ServerProcess::watch_heartbeat(uint64_t heartbeat, bool attached, bool work_outstanding,
                                    std::chrono::milliseconds timeout, SteadyTime now) {
  if (!serving()) return false;
  if (attached && !attached_) {
    attached_ = true;
    if (colormap_only_) {
      colormap_only_ = false;
      spdlog::info("texstream-server pid {} attached: leaving colormap-only mode", pid_);
    }
  }
  // Only a stall while work waits counts: an idle server may legitimately sleep between doorbells.
  if (heartbeat != last_heartbeat_ || !work_outstanding) {
    last_heartbeat_ = heartbeat;
    last_progress_ = now;
    return false;
  }
  const auto limit = attached ? timeout : std::max(timeout, policy_.startup_grace);
  if (now - last_progress_ <= limit) return false;
  kill("heartbeat stalled for " +
       std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(now - last_progress_).count()) +
       " ms with requests outstanding" + (attached ? "" : " (never attached)"));
  return true;
}

void ServerProcess::kill(const std::string& why) {
  if (pid_ <= 0 || killing_) return;
  spdlog::error("killing texstream-server pid {}: {}", pid_, why);
  ::kill(pid_, SIGKILL);
  killing_ = true;
  kill_reason_ = why;
}

ServerState ServerProcess::state() const {
  if (pid_ > 0 && !killing_) return ServerState::kRunning;
  if (colormap_only_) return ServerState::kColormapOnly;
  if (spawns_ > 0) return ServerState::kBackingOff;
  return ServerState::kStopped;
}

}  // namespace texstream
