#include "texstream/stream/server_process.hpp"

#include <pthread.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <spdlog/spdlog.h>
#include <algorithm>
#include <cerrno>
#include <cstring>
#include <system_error>
#include <utility>

#include "texstream/common/child_process.hpp"
#include "texstream/protocol/liveness.hpp"

namespace texstream::stream {

namespace {

// How often the idle spawner thread looks for a posted spawn: small next to the restart back-off (50 ms).
constexpr auto kPostPoll = std::chrono::milliseconds(2);

std::string describe_status(int status) {
  if (WIFEXITED(status)) return "exited with status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    return "killed by signal " + std::to_string(sig) + " (" + strsignal(sig) + ")";
  }
  return "ended with wait status " + std::to_string(status);
}

// The child starts with no blocked signals and default dispositions for the signals a renderer may ignore or
// catch, so `--spawned` servers die of SIGTERM/SIGPIPE as expected. Every descriptor past stdio is closed in
// the child: our pidfds, the shared-memory fd and the Vulkan driver's files must not leak into the server or
// keep them alive after we close them.
SpawnOptions server_spawn_options() {
  SpawnOptions o;
  o.signals.reset = true;
  o.signals.defaults = {SIGPIPE, SIGINT, SIGTERM, SIGHUP, SIGCHLD, SIGUSR1, SIGUSR2};
  o.fds.push_back(SpawnFd::close_from(3));
  return o;
}

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
    case ServerState::kStopped:
      return "stopped";
    case ServerState::kRunning:
      return "running";
    case ServerState::kBackingOff:
      return "backing off";
    case ServerState::kColormapOnly:
      return "colormap only";
  }
  return "?";
}

ServerProcess::ServerProcess(ServerCommand command, RestartPolicy policy)
    : command_(std::move(command)), policy_(policy) {
  // spdlog's registry (the default logger) is made on first use. Made here, before the spawner thread
  // starts, its creation happens-before the thread's first log line for every tool, TSan included: the
  // function-local static's guard lives in the uninstrumented libspdlog, so when the spawner and this
  // thread logged first at the same moment, TSan reported the logger's level as a race (CI, twice in a run).
  spdlog::default_logger_raw();
  spawner_ = std::thread([this] { spawner_main(); });
}

ServerProcess::~ServerProcess() {
  {
    std::unique_lock lock(mutex_);
    shared_.stopping = true;  // a posted spawn not yet taken is dropped
    changed_.notify_all();
    // A spawn in flight publishes its pid within milliseconds; then the child is ours to end.
    changed_.wait(lock, [&] { return !shared_.spawning; });
    if (shared_.pid > 0 && !shared_.dying && !shared_.exit) {
      ::kill(shared_.pid, SIGTERM);
      // Let it log its exit; a server that ignores SIGTERM for 500 ms is killed.
      constexpr auto kTermGrace = std::chrono::milliseconds(500);
      if (!changed_.wait_for(lock, kTermGrace, [&] { return shared_.dying || shared_.exit.has_value(); })) {
        ::kill(shared_.pid, SIGKILL);
      }
    }
  }
  spawner_.join();  // it reaps the child, then sees `stopping`
}

void ServerProcess::spawner_main() {
  // Process-directed signals (SIGINT, SIGCHLD, ...) go to the renderer's other threads, never interrupt
  // this one; the child gets its own mask through posix_spawn attributes.
  sigset_t all;
  sigfillset(&all);
  pthread_sigmask(SIG_BLOCK, &all, nullptr);
  pthread_setname_np(pthread_self(), "ts-spawner");
  for (;;) {
    {
      std::unique_lock lock(mutex_);
      // Polled, not notified: a notify from spawn_if_due woke this thread inside the frame's IPC section,
      // and on 2 busy cores the woken thread took the CPU from the frame thread for the whole posix_spawn
      // (measured 1-3 ms per spawn_if_due). A poll lands at a random instant of the frame instead. It runs only
      // between a child's death and the next spawn (while a child lives, this thread waits in waitid).
      while (!changed_.wait_for(lock, kPostPoll, [&] { return shared_.stopping || shared_.spawn_requested; })) {
      }
      if (shared_.stopping) return;
      shared_.spawn_requested = false;
      shared_.spawning = true;
    }
    run_child();
  }
}

void ServerProcess::run_child() {
  const Result<pid_t> spawned = spawn_process(command_.argv(), server_spawn_options());
  if (!spawned) {
    spdlog::error("texstream-server '{}' could not be spawned: {}", command_.executable.string(),
                  spawned.error().message);
    std::lock_guard lock(mutex_);
    shared_.spawning = false;
    shared_.exit = ServerExit{0, "could not be spawned: " + spawned.error().message, 0, -1, false, {}};
    changed_.notify_all();
    return;
  }
  const pid_t pid = *spawned;
  {
    std::lock_guard lock(mutex_);
    shared_.spawning = false;
    shared_.pid = pid;
    shared_.dying = false;
    if (shared_.kill_requested) ::kill(pid, SIGKILL);  // killed while being spawned (kill() logged why)
    shared_.kill_requested = false;
    changed_.notify_all();
  }
  spdlog::info("texstream-server started: pid {} segment '{}'", pid, command_.segment_name);

  // Wait for its end without reaping it (WNOWAIT): until we say `dying`, the frame thread may still signal
  // the pid, which stays this child's (a zombie keeps it) until the waitpid below.
  siginfo_t info{};
  int r;
  do {
    r = ::waitid(P_PID, static_cast<id_t>(pid), &info, WEXITED | WNOWAIT);
  } while (r < 0 && errno == EINTR);
  {
    std::lock_guard lock(mutex_);
    shared_.dying = true;
  }
  int status = 0;
  pid_t w;
  do {
    w = ::waitpid(pid, &status, 0);
  } while (w < 0 && errno == EINTR);
  ServerExit e;
  e.pid = pid;
  if (w == pid) {
    e.how = describe_status(status);
    e.term_signal = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
    e.exit_status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  } else {
    // ECHILD: someone else reaped it (SIGCHLD set to SIG_IGN auto-reaps). The waitid answer, if any, still
    // says how it ended.
    e.how = std::string("vanished (waitpid: ") + std::strerror(errno) + ")";
    if (r == 0 && (info.si_code == CLD_KILLED || info.si_code == CLD_DUMPED)) e.term_signal = info.si_status;
  }
  std::lock_guard lock(mutex_);
  if (shared_.exit_told_early) {
    shared_.exit_told_early = false;  // reap() has told this death already
  } else {
    shared_.exit = std::move(e);
  }
  changed_.notify_all();
}

int ServerProcess::pid() const {
  std::unique_lock lock(mutex_);
  // A posted spawn is answered within milliseconds; the bound only keeps a wedged spawner from hanging a
  // diagnostic call.
  constexpr auto kSpawnAnswer = std::chrono::seconds(5);
  changed_.wait_for(lock, kSpawnAnswer, [&] { return !shared_.spawn_requested && !shared_.spawning; });
  return shared_.pid;
}

bool ServerProcess::spawn_if_due(SteadyTime now) {
  if (child_ || now < next_spawn_at_) return false;
  {
    std::lock_guard lock(mutex_);  // held by the spawner only for a few stores, never across a system call
    shared_.spawn_requested = true;
    shared_.kill_requested = false;
  }
  // No notify: the spawner polls (see spawner_main).
  ++spawns_;
  spawned_at_ = now;
  last_progress_ = now;
  last_heartbeat_ = 0;
  attached_ = false;
  killing_ = false;
  kill_reason_.clear();
  kill_hung_ = false;
  child_ = true;
  spdlog::debug("texstream-server spawn #{} posted to the spawner thread", spawns_);
  return true;
}

std::optional<ServerExit> ServerProcess::reap(SteadyTime now) {
  if (!child_) return std::nullopt;
  std::optional<ServerExit> e;
  {
    // try_lock: a spawner preempted while holding the lock must not stall the frame; busy means
    // "look again next frame".
    std::unique_lock lock(mutex_, std::try_to_lock);
    if (lock.owns_lock() && shared_.exit) {
      e = std::move(shared_.exit);
      shared_.exit.reset();
      shared_.pid = -1;
      shared_.dying = false;
      shared_.kill_requested = false;
    } else if (lock.owns_lock() && shared_.pid > 0 && !shared_.spawning) {
      // The spawner tells a death only once the scheduler runs it; on a loaded machine that took 270 ms.
      // A non-blocking waitid WNOWAIT peek (any thread of the process may wait for its children) tells it
      // now; the child stays a zombie, so its pid cannot be reused until the spawner's waitpid.
      siginfo_t info{};
      if (::waitid(P_PID, static_cast<id_t>(shared_.pid), &info, WEXITED | WNOHANG | WNOWAIT) == 0 &&
          info.si_pid == shared_.pid) {
        ServerExit early;
        early.pid = shared_.pid;
        if (info.si_code == CLD_EXITED) {
          early.how = "exited with status " + std::to_string(info.si_status);
          early.exit_status = info.si_status;
        } else {
          early.term_signal = info.si_status;
          early.how = "killed by signal " + std::to_string(info.si_status) + " (" + strsignal(info.si_status) + ")";
        }
        e = std::move(early);
        shared_.exit_told_early = true;
        shared_.pid = -1;
        shared_.kill_requested = false;
      }
    }
  }
  if (!e) {
    if (colormap_only_ && now - spawned_at_ >= policy_.crash_window) {
      colormap_only_ = false;
      spdlog::info("texstream-server spawn #{} has run for {} s: leaving colormap-only mode", spawns_,
                   std::chrono::duration_cast<std::chrono::seconds>(policy_.crash_window).count());
    }
    return std::nullopt;
  }
  e->killed_by_us = killing_;
  e->kill_reason = kill_reason_;
  e->hung = killing_ && kill_hung_;
  // SIGKILL that we did not send came from outside (OOM killer, an operator, texstream-chaos): the server did
  // nothing wrong. Anything else it ended by itself (exit, SIGSEGV, SIGABRT, ...), could not be spawned, or
  // we killed it: a crash.
  const bool outside_kill = e->term_signal == SIGKILL && !killing_;
  child_ = false;
  killing_ = false;
  kill_reason_.clear();
  kill_hung_ = false;
  attached_ = false;
  record_death(now, !outside_kill);
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
      spdlog::info("texstream-server spawn #{} attached: leaving colormap-only mode", spawns_);
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
  // Hung by its own doing, or stopped from outside (SIGSTOP: texstream-chaos, a debugger): only the first is
  // charged to the textures it was loading (StreamClient::charge_hang).
  const bool stopped = process_stopped(pid());
  kill("heartbeat stalled for " +
       std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(now - last_progress_).count()) +
       " ms with requests outstanding" + (attached ? "" : " (never attached)") + (stopped ? " (stopped)" : ""));
  kill_hung_ = attached && killing_ && !stopped;
  return true;
}

void ServerProcess::kill(const std::string& why) {
  if (!child_ || killing_) return;
  int pid = -1;
  {
    std::lock_guard lock(mutex_);
    if (shared_.exit || shared_.dying) {
      // Already dead of something else (e.g. an outside SIGKILL the watchdog noticed first as a stall): not
      // our kill, so reap() must not count it as a crash of ours. It reports the death at its next call.
      spdlog::warn("texstream-server spawn #{} is already dead; not killing it ({})", spawns_, why);
      return;
    }
    if (shared_.pid > 0) {
      pid = shared_.pid;
      ::kill(pid, SIGKILL);  // under the lock: the spawner cannot reap it meanwhile (it says `dying` first)
    } else {
      shared_.kill_requested = true;  // still being spawned
    }
  }
  killing_ = true;
  kill_reason_ = why;
  if (pid > 0) {
    spdlog::error("killing texstream-server pid {}: {}", pid, why);
  } else {
    spdlog::error("killing texstream-server spawn #{} as soon as it exists: {}", spawns_, why);
  }
}

ServerState ServerProcess::state() const {
  if (child_ && !killing_) return ServerState::kRunning;
  if (colormap_only_) return ServerState::kColormapOnly;
  if (spawns_ > 0) return ServerState::kBackingOff;
  return ServerState::kStopped;
}

}  // namespace texstream::stream
