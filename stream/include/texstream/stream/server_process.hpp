#pragma once
// The renderer's supervisor of its texstream-server child: spawn (posix_spawn), death told by the kernel
// (waitid), reaping, restart with exponential back-off, a "colormap only" mode after repeated crashes, and a
// progress watchdog that SIGKILLs a hung server.
//
// Frame-safe: every method but pid() and the destructor returns at once. posix_spawn (a vfork that suspends the caller
// until the child has exec'd: milliseconds on a loaded machine) and the wait for the child's death run on a
// long-lived *spawner thread* owned by this object; the frame thread only posts requests and reads results
// under a mutex that is never held across a system call that can block. The spawner thread lives as long as
// this object, which kills and reaps its child before it goes: a `--spawned` server asks for
// PR_SET_PDEATHSIG, which Linux fires when the *thread* that spawned it exits, not the process.
//
// Time is passed in (`now`), never read here, so the back-off schedule can be tested with a virtual clock.
// One thread (the renderer's frame loop) calls the methods.
//
// The caller (StreamClient) sequences what must happen around a death: reap() reports it, the caller resets
// the shared segment (only after the reap: the dead process was the sole writer of its words), and only
// then calls spawn_if_due(), which posts a spawn once the back-off has passed.
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"

namespace texstream::stream {

using SteadyTime = std::chrono::steady_clock::time_point;

// `texstream-server --segment NAME --scene DIR [--config FILE] [--set part.key=value]... --spawned`
struct ServerCommand {
  std::filesystem::path executable;
  std::string segment_name;
  std::filesystem::path scene_dir;
  std::filesystem::path config_file;   // empty: no --config
  std::vector<std::string> overrides;  // each passed as `--set <override>`
  std::vector<std::string> argv() const;
};

// `server.executable`, or `texstream-server` next to the running binary (/proc/self/exe). Fails, naming the
// path and the key, if the file is not there or not executable.
Result<std::filesystem::path> resolve_server_executable(const Config& config);

// Two kinds of death (issue 9). A *crash* is a server that ended by itself (any exit, SIGSEGV, SIGABRT...),
// could not be spawned, or that we killed (hung, protocol violation): crashes back off exponentially and,
// repeated, lead to colormap-only mode. A SIGKILL we did not send came from outside (OOM killer, an operator,
// texstream-chaos): that server did nothing wrong, so it is replaced after first_delay and does not count
// toward the back-off — a restart storm of 100 kills in 60 s must end in normal streaming within 5 s, which
// exponential back-off towards colormap-only (30 s retries) would make impossible.
struct RestartPolicy {
  std::chrono::milliseconds first_delay{50};  // first restart after a crash; doubles per recent crash
  std::chrono::milliseconds max_delay{5000};  // cap of the doubling
  uint32_t crash_limit = 5;                   // this many crashes within crash_window → colormap only
  std::chrono::milliseconds crash_window{30000};
  std::chrono::milliseconds slow_retry{30000};  // colormap only: still try this often
  // Until the server reports `attached`, it may still be loading its scene and config: its heartbeat is
  // not expected to move yet, so the watchdog waits this long instead of the heartbeat timeout.
  std::chrono::milliseconds startup_grace{10000};
};

enum class ServerState : uint8_t {
  kStopped,       // never started (or spawning disabled)
  kRunning,       // a child process exists and has not been killed by us
  kBackingOff,    // dead; a restart is scheduled
  kColormapOnly,  // crashed crash_limit times within crash_window: restarts slowed to slow_retry
};
const char* to_string(ServerState state);

// texstream-server's exit status for bad arguments, configuration or scene (texture_server/src/main.cpp):
// a refusal that a restart cannot change.
inline constexpr int kServerExitBadConfig = 2;

struct ServerExit {
  int pid = 0;
  std::string how;       // "exited with status 3", "killed by signal 9", "could not be spawned: ..."
  int term_signal = 0;   // the signal that ended it; 0 if it exited or was never spawned
  int exit_status = -1;  // its exit status if it exited (texstream-server: 2 = bad arguments, configuration
                         // or scene, see kServerExitBadConfig); -1 otherwise
  bool killed_by_us = false;
  std::string kill_reason;  // why we killed it, if we did
  bool hung = false;        // we killed it because its heartbeat stalled while it was serving (attached)
};

class ServerProcess {
 public:
  // Starts the spawner thread (it spawns nothing until spawn_if_due()).
  ServerProcess(ServerCommand command, RestartPolicy policy);
  // Kills the child (SIGTERM, then SIGKILL after a short grace), lets the spawner reap it and joins the
  // spawner. May block briefly (at most the grace plus a spawn in flight).
  ~ServerProcess();
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  // Posts a spawn if there is no child and the back-off has passed; returns true if it posted one. The
  // spawner thread runs posix_spawn; a failure counts as a crash and is reported by a later reap().
  // Requests may be queued in the (reset) segment at once: the server reads them once it attaches.
  bool spawn_if_due(SteadyTime now);

  // Non-blocking. If the child has died (the spawner reaped it) or could not be spawned, returns how it
  // ended and schedules the next spawn by the back-off policy.
  std::optional<ServerExit> reap(SteadyTime now);

  // Progress watchdog. `heartbeat` is ServerBlock.heartbeat, `attached` ServerBlock.attached. The server is
  // hung if its heartbeat has not moved for `timeout` (startup_grace before it attached) while
  // `work_outstanding`. A hung server is SIGKILLed (reap() then reports it). Returns true if it killed.
  // Also ends colormap-only mode once a child has attached (it works again).
  bool watch_heartbeat(uint64_t heartbeat, bool attached, bool work_outstanding, std::chrono::milliseconds timeout,
                       SteadyTime now);

  // SIGKILL now (a protocol violation, a hang); a child still being spawned is killed as soon as it exists.
  // The child stays until reap() reports it. No-op if none.
  void kill(const std::string& why);

  // A spawn was posted and its end not yet reported by reap().
  bool has_child() const { return child_; }
  // A child exists (or is being spawned) and we have not decided to kill it: requests may be sent to it.
  bool serving() const { return child_ && !killing_; }
  // The child's pid; -1 without a child or after a failed spawn. Diagnostics and tests only, not for the
  // frame loop: it waits (milliseconds) for a spawn in flight to return.
  int pid() const;
  ServerState state() const;
  SteadyTime next_spawn_at() const { return next_spawn_at_; }
  SteadyTime spawned_at() const { return spawned_at_; }
  uint64_t crashes() const { return crashes_total_; }  // deaths that counted as crashes (see RestartPolicy)
  uint64_t spawns() const { return spawns_; }
  uint64_t deaths() const { return deaths_total_; }
  const ServerCommand& command() const { return command_; }

 private:
  // `crash`: see RestartPolicy. A crash backs off (and may enter colormap-only); any other death restarts
  // after first_delay.
  void record_death(SteadyTime now, bool crash);
  // The spawner thread: waits for a posted spawn, spawns, publishes the pid, waits for the child's death,
  // reaps it and publishes how it ended; until the destructor says stop.
  void spawner_main();
  // Spawner thread: one child's life from posix_spawn to its reaped exit.
  void run_child();

  // Immutable after construction (the spawner thread reads command_).
  const ServerCommand command_;
  const RestartPolicy policy_;

  // ---- the frame thread's own state ----
  bool child_ = false;
  bool killing_ = false;
  std::string kill_reason_;
  bool kill_hung_ = false;  // kill_reason_ is an attached server's heartbeat stall
  SteadyTime spawned_at_{};
  SteadyTime next_spawn_at_{};
  std::deque<SteadyTime> recent_deaths_;  // within crash_window
  bool colormap_only_ = false;
  uint64_t spawns_ = 0;
  uint64_t deaths_total_ = 0;
  uint64_t crashes_total_ = 0;
  bool attached_ = false;  // the current child reported `attached` to watch_heartbeat (ends colormap-only)
  uint64_t last_heartbeat_ = 0;
  SteadyTime last_progress_{};

  // ---- shared between the frame thread and the spawner thread, guarded by mutex_ ----
  struct Shared {
    bool spawn_requested = false;  // frame → spawner
    bool stopping = false;         // destructor → spawner
    bool kill_requested = false;   // frame → spawner: SIGKILL the child as soon as posix_spawn returns
    bool spawning = false;         // the spawner is inside posix_spawn
    int pid = -1;                  // the current child, from spawn until reap() takes its exit
    // The child has terminated (waitid WNOWAIT told so) and is about to be reaped: its pid must not be
    // signalled any more (once reaped it may belong to another process).
    bool dying = false;
    std::optional<ServerExit> exit;  // how the child ended (or why it could not be spawned), for reap()
    // reap() told the death itself (a non-blocking waitid WNOWAIT peek) before the spawner published it:
    // the spawner still reaps the child but drops its own report of it.
    bool exit_told_early = false;
  };
  mutable std::mutex mutex_;
  mutable std::condition_variable changed_;  // any change of shared_ (pid() waits on it)
  Shared shared_;
  std::thread spawner_;  // last: started once every member above exists
};

}  // namespace texstream::stream
