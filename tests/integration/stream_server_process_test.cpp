// ServerProcess against stand-in executables (small shell scripts): the command line it passes, death told
// and reaped by the spawner thread without blocking the caller, the back-off schedule (driven by a virtual
// clock), the colormap-only mode after repeated crashes, the heartbeat watchdog, a kill posted while the
// child is still being spawned, the parent-death signal tied to the spawner thread (not the caller's), and
// the kill on destruction.
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "../support/patience.hpp"
#include "texstream/protocol/liveness.hpp"
#include "texstream/stream/server_process.hpp"

namespace texstream {
namespace {

using namespace std::chrono_literals;
using test::kHangAfter;
namespace fs = std::filesystem;

struct TempDir {
  fs::path path;
  TempDir() {
    static int n = 0;
    path =
        fs::temp_directory_path() / ("texstream-test-proc-" + std::to_string(::getpid()) + "-" + std::to_string(n++));
    fs::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

fs::path write_script(const fs::path& dir, const std::string& name, const std::string& body) {
  const fs::path p = dir / name;
  std::ofstream(p) << "#!/bin/sh\n" << body << "\n";
  fs::permissions(p, fs::perms::owner_all);
  return p;
}

stream::ServerCommand command(const fs::path& exe) {
  return stream::ServerCommand{exe, "texstream-seg", "/scenes/tiny", "", {}};
}

// Polls reap() (real time passes, the virtual `now` does not) until the child's death is reported.
std::optional<stream::ServerExit> wait_reap(stream::ServerProcess& p, stream::SteadyTime now) {
  const auto deadline = std::chrono::steady_clock::now() + kHangAfter;
  while (std::chrono::steady_clock::now() < deadline) {
    if (auto e = p.reap(now)) return e;
    std::this_thread::sleep_for(1ms);
  }
  return std::nullopt;
}

// The pid once the spawner thread has started the child (spawn_if_due only posts the spawn).
int wait_pid(const stream::ServerProcess& p) {
  const auto deadline = std::chrono::steady_clock::now() + kHangAfter;
  while (std::chrono::steady_clock::now() < deadline) {
    if (p.pid() > 0) return p.pid();
    std::this_thread::sleep_for(1ms);
  }
  return -1;
}

TEST(ServerCommand, ArgvFollowsTheServerCommandLine) {
  stream::ServerCommand c{"/opt/bin/texstream-server",
                          "texstream-42",
                          "/data/city",
                          "/etc/ts.toml",
                          {"server.worker_threads=1", "protocol.heartbeat_timeout_ms=500"}};
  EXPECT_EQ(c.argv(),
            (std::vector<std::string>{"/opt/bin/texstream-server", "--segment", "texstream-42", "--scene", "/data/city",
                                      "--config", "/etc/ts.toml", "--set", "server.worker_threads=1", "--set",
                                      "protocol.heartbeat_timeout_ms=500", "--spawned"}));
  c.config_file.clear();
  c.overrides.clear();
  EXPECT_EQ(c.argv(), (std::vector<std::string>{"/opt/bin/texstream-server", "--segment", "texstream-42", "--scene",
                                                "/data/city", "--spawned"}));
}

TEST(ServerProcess, PassesTheCommandLineToTheChild) {
  TempDir dir;
  const fs::path out = dir.path / "args.txt";
  const fs::path exe = write_script(dir.path, "record-args", "printf '%s\\n' \"$@\" > '" + out.string() + "'");
  stream::ServerCommand cmd{exe, "texstream-seg", "/scenes/tiny", "/etc/cfg.toml", {"server.log_level=debug"}};
  stream::ServerProcess p(cmd, {});
  const stream::SteadyTime t0 = std::chrono::steady_clock::now();
  ASSERT_TRUE(p.spawn_if_due(t0));
  EXPECT_EQ(p.state(), stream::ServerState::kRunning);
  const auto e = wait_reap(p, t0);
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->how, "exited with status 0");
  std::ifstream in(out);
  std::stringstream ss;
  ss << in.rdbuf();
  EXPECT_EQ(ss.str(),
            "--segment\ntexstream-seg\n--scene\n/scenes/tiny\n--config\n/etc/cfg.toml\n--set\n"
            "server.log_level=debug\n--spawned\n");
}

TEST(ServerProcess, BacksOffExponentiallyThenGoesColormapOnly) {
  TempDir dir;
  const fs::path exe = write_script(dir.path, "crash", "exit 3");
  stream::ServerProcess p(command(exe), stream::RestartPolicy{});  // 50 ms doubling, 5 crashes in 30 s, slow retry 30 s
  stream::SteadyTime now = std::chrono::steady_clock::now();
  EXPECT_EQ(p.state(), stream::ServerState::kStopped);
  ASSERT_TRUE(p.spawn_if_due(now));
  // Delays after the 1st..4th crash: 50, 100, 200, 400 ms.
  for (int64_t delay_ms : {50, 100, 200, 400}) {
    const auto e = wait_reap(p, now);
    ASSERT_TRUE(e.has_value());
    EXPECT_EQ(e->how, "exited with status 3");
    EXPECT_FALSE(e->killed_by_us);
    EXPECT_EQ(p.state(), stream::ServerState::kBackingOff);
    EXPECT_FALSE(p.spawn_if_due(now + std::chrono::milliseconds(delay_ms - 1))) << delay_ms;
    now += std::chrono::milliseconds(delay_ms);
    ASSERT_TRUE(p.spawn_if_due(now)) << delay_ms;
  }
  // The 5th crash within 30 s: colormap only, next try in 30 s.
  ASSERT_TRUE(wait_reap(p, now).has_value());
  EXPECT_EQ(p.state(), stream::ServerState::kColormapOnly);
  EXPECT_FALSE(p.spawn_if_due(now + 29s));
  now += 30s;
  ASSERT_TRUE(p.spawn_if_due(now)) << "colormap only still retries slowly";
  ASSERT_TRUE(wait_reap(p, now).has_value());
  EXPECT_EQ(p.state(), stream::ServerState::kColormapOnly) << "a crash on the slow retry keeps it colormap only";
  EXPECT_EQ(p.next_spawn_at(), now + 30s);
  EXPECT_EQ(p.spawns(), 6u);
  EXPECT_EQ(p.deaths(), 6u);
}

TEST(ServerProcess, OldCrashesAgeOutOfTheWindow) {
  TempDir dir;
  const fs::path exe = write_script(dir.path, "crash", "exit 1");
  stream::ServerProcess p(command(exe), stream::RestartPolicy{});
  stream::SteadyTime now = std::chrono::steady_clock::now();
  ASSERT_TRUE(p.spawn_if_due(now));
  ASSERT_TRUE(wait_reap(p, now).has_value());
  now += 50ms;
  ASSERT_TRUE(p.spawn_if_due(now));
  ASSERT_TRUE(wait_reap(p, now).has_value());  // 2 crashes in the window: next delay 100 ms
  EXPECT_EQ(p.next_spawn_at(), now + 100ms);
  now += 31s;  // both crashes are now older than the 30 s window
  ASSERT_TRUE(p.spawn_if_due(now));
  ASSERT_TRUE(wait_reap(p, now).has_value());
  EXPECT_EQ(p.next_spawn_at(), now + 50ms) << "back to the first delay";
}

TEST(ServerProcess, ColormapOnlyEndsAfterAServerRunsAWholeWindow) {
  TempDir dir;
  const fs::path flag = dir.path / "stay";
  // Crashes until the flag file exists, then stays up.
  const fs::path exe = write_script(dir.path, "flaky", "[ -e '" + flag.string() + "' ] && exec sleep 60\nexit 2");
  stream::RestartPolicy policy;
  policy.crash_limit = 2;
  stream::ServerProcess p(command(exe), policy);
  stream::SteadyTime now = std::chrono::steady_clock::now();
  ASSERT_TRUE(p.spawn_if_due(now));
  ASSERT_TRUE(wait_reap(p, now).has_value());
  now += 50ms;
  ASSERT_TRUE(p.spawn_if_due(now));
  ASSERT_TRUE(wait_reap(p, now).has_value());
  EXPECT_EQ(p.state(), stream::ServerState::kColormapOnly);
  std::ofstream(flag) << "1";
  now += 30s;
  ASSERT_TRUE(p.spawn_if_due(now));
  EXPECT_EQ(p.state(), stream::ServerState::kRunning);
  std::this_thread::sleep_for(50ms);
  EXPECT_FALSE(p.reap(now + 29s).has_value());
  EXPECT_FALSE(p.reap(now + 30s).has_value());  // a whole window alive: no longer colormap only
  p.kill("test");
  ASSERT_TRUE(wait_reap(p, now + 30s).has_value());
  EXPECT_EQ(p.state(), stream::ServerState::kBackingOff) << "one crash after a stable run is an ordinary restart";
}

TEST(ServerProcess, SpawnFailureCountsAsACrash) {
  TempDir dir;
  // Exists and is executable for access(), but exec fails: not a valid program.
  const fs::path exe = dir.path / "not-a-program";
  std::ofstream(exe) << "\x7f"
                        "ELF garbage";
  fs::permissions(exe, fs::perms::owner_all);
  stream::ServerProcess p(command(exe), {});
  const stream::SteadyTime now = std::chrono::steady_clock::now();
  EXPECT_TRUE(p.spawn_if_due(now)) << "posted to the spawner thread";
  const auto e = wait_reap(p, now);
  ASSERT_TRUE(e.has_value());
  EXPECT_NE(e->how.find("could not be spawned"), std::string::npos) << e->how;
  EXPECT_EQ(e->pid, 0);
  EXPECT_EQ(p.state(), stream::ServerState::kBackingOff);
  EXPECT_EQ(p.next_spawn_at(), now + 50ms);
  EXPECT_EQ(p.crashes(), 1u);
}

TEST(ServerProcess, KillPostedWhileSpawningKillsTheChildOnceItExists) {
  TempDir dir;
  const fs::path exe = write_script(dir.path, "hang", "exec sleep 60");
  stream::ServerProcess p(command(exe), {});
  const stream::SteadyTime now = std::chrono::steady_clock::now();
  ASSERT_TRUE(p.spawn_if_due(now));
  p.kill("protocol violation before it even started");  // most likely before posix_spawn has returned
  EXPECT_FALSE(p.serving());
  const auto e = wait_reap(p, now);
  ASSERT_TRUE(e.has_value()) << "the kill must reach a child spawned after it was asked for";
  EXPECT_TRUE(e->killed_by_us);
  EXPECT_EQ(e->term_signal, SIGKILL);
  EXPECT_EQ(e->kill_reason, "protocol violation before it even started");
  EXPECT_EQ(p.crashes(), 1u) << "a server we killed counts as a crash";
}

TEST(ServerProcess, SigkillFromOutsideIsNoCrash) {
  TempDir dir;
  const fs::path exe = write_script(dir.path, "hang", "exec sleep 60");
  stream::ServerProcess p(command(exe), {});
  const stream::SteadyTime now = std::chrono::steady_clock::now();
  ASSERT_TRUE(p.spawn_if_due(now));
  const int pid = wait_pid(p);
  ASSERT_GT(pid, 0);
  ::kill(pid, SIGKILL);  // texstream-chaos, the OOM killer
  const auto e = wait_reap(p, now);
  ASSERT_TRUE(e.has_value());
  EXPECT_FALSE(e->killed_by_us);
  EXPECT_EQ(e->pid, pid);
  EXPECT_EQ(e->term_signal, SIGKILL);
  EXPECT_EQ(p.crashes(), 0u);
  EXPECT_EQ(p.next_spawn_at(), now + 50ms) << "replaced after first_delay";
  EXPECT_EQ(p.pid(), -1);
}

// PR_SET_PDEATHSIG fires when the thread that spawned the child exits. The spawner thread lives as long as
// the ServerProcess, so a child must survive the end of the thread that called spawn_if_due.
TEST(ServerProcess, ChildSurvivesTheThreadThatAskedForIt) {
  TempDir dir;
  const fs::path exe = write_script(dir.path, "pdeathsig", "exec setpriv --pdeathsig KILL -- sleep 60");
  stream::ServerProcess p(command(exe), {});
  const stream::SteadyTime now = std::chrono::steady_clock::now();
  std::thread([&] { ASSERT_TRUE(p.spawn_if_due(now)); }).join();
  const int pid = wait_pid(p);
  ASSERT_GT(pid, 0);
  std::this_thread::sleep_for(300ms);  // setpriv has set the signal and exec'd sleep by now
  EXPECT_FALSE(p.reap(now).has_value()) << "killed by the parent-death signal of an ended thread";
  EXPECT_TRUE(p.serving());
}

TEST(ServerProcess, WatchdogKillsAServerWhoseHeartbeatStallsWithWorkOutstanding) {
  TempDir dir;
  const fs::path exe = write_script(dir.path, "hang", "exec sleep 60");
  stream::RestartPolicy policy;
  policy.startup_grace = 1000ms;
  stream::ServerProcess p(command(exe), policy);
  stream::SteadyTime now = std::chrono::steady_clock::now();
  ASSERT_TRUE(p.spawn_if_due(now));
  const auto timeout = 100ms;
  // Not attached yet: the startup grace (1 s) applies instead of the 100 ms timeout.
  EXPECT_FALSE(p.watch_heartbeat(0, false, true, timeout, now + 500ms));
  EXPECT_FALSE(p.watch_heartbeat(0, false, true, timeout, now + 1000ms));
  // Attached and beating: fine. Idle with a still heartbeat: fine.
  EXPECT_FALSE(p.watch_heartbeat(1, true, true, timeout, now + 1050ms));
  EXPECT_FALSE(p.watch_heartbeat(1, true, false, timeout, now + 5000ms));
  EXPECT_FALSE(p.watch_heartbeat(1, true, true, timeout, now + 5100ms));
  EXPECT_TRUE(p.serving());
  EXPECT_TRUE(p.watch_heartbeat(1, true, true, timeout, now + 5101ms));
  EXPECT_FALSE(p.serving()) << "being killed: no new requests";
  EXPECT_TRUE(p.has_child()) << "until reaped";
  const auto e = wait_reap(p, now + 5101ms);
  ASSERT_TRUE(e.has_value());
  EXPECT_TRUE(e->killed_by_us);
  EXPECT_NE(e->how.find("signal 9"), std::string::npos) << e->how;
  EXPECT_NE(e->kill_reason.find("heartbeat stalled"), std::string::npos) << e->kill_reason;
}

TEST(ServerProcess, DestructorKillsAndReapsTheChild) {
  TempDir dir;
  const fs::path exe = write_script(dir.path, "ignore-term", "trap '' TERM\nwhile :; do sleep 0.05; done");
  int pid = -1;
  uint64_t start = 0;
  const auto t0 = std::chrono::steady_clock::now();
  {
    stream::ServerProcess p(command(exe), {});
    ASSERT_TRUE(p.spawn_if_due(t0));
    pid = wait_pid(p);
    ASSERT_GT(pid, 0);
    std::this_thread::sleep_for(100ms);  // let the shell install its trap
    start = process_start_time(pid).value_or(0);
    ASSERT_NE(start, 0u);
  }
  EXPECT_FALSE(process_alive(pid, start)) << "SIGTERM ignored: SIGKILL after the grace";
  // The destructor's 500 ms SIGTERM grace, then SIGKILL: it does not wait for the child's good will.
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 500ms + test::promptly(500ms));
}

TEST(ResolveServerExecutable, NamesThePathAndTheKey) {
  Config c;
  c.server.executable = "/nonexistent/dir/texstream-server";
  auto r = stream::resolve_server_executable(c);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("/nonexistent/dir/texstream-server"), std::string::npos);
  EXPECT_NE(r.error().message.find("server.executable"), std::string::npos);
  c.server.executable.clear();
  r = stream::resolve_server_executable(c);  // next to this test binary
  if (!r.ok()) {
    EXPECT_NE(r.error().message.find("texstream-server"), std::string::npos);
    EXPECT_NE(r.error().message.find("next to"), std::string::npos) << r.error().message;
  } else {
    EXPECT_EQ(r->filename(), "texstream-server");
  }
  c.server.executable = "/bin/sh";
  r = stream::resolve_server_executable(c);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(*r, fs::path("/bin/sh"));
}

}  // namespace
}  // namespace texstream
