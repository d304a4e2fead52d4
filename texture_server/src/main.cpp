// texstream-server: serves one renderer through the shared segment the renderer created.
//
//   texstream-server --segment NAME --scene DIR [--config FILE] [--set part.key=value]... [--spawned]
//
// Spawned (--spawned): serves the renderer that started it and exits with it. Standalone (no --spawned):
// waits for a renderer to create the segment if there is none yet, and when the renderer dies, waits for the
// next one — a renderer configured with the same
// protocol.segment_name recreates the segment under that name with a new epoch — and serves it.
// SIGUSR1 logs the statistics (server_stats.hpp); they are also logged at exit.
//
// Exit codes: 0 stopped (SIGTERM/SIGINT) or the renderer exited; 2 bad arguments, configuration or scene;
// 3 the segment cannot be opened or its header does not match this build (the message names the field; a
// standalone server whose segment does not exist yet waits for a renderer to create it instead);
// 4 the renderer broke the ring protocol; 5 the storage origin did not answer at start (a restart may
// succeed: the renderer retries it like a crash, while 2 ends its run after three in a row).
#include <sched.h>
#include <signal.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/common/memory_info.hpp"
#include "texstream/protocol/liveness.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/server/dispatch/server.hpp"
#include "texstream/server/storage/storage_stack.hpp"

namespace {

constexpr int kExitOk = 0;
constexpr int kExitBadArguments = 2;
constexpr int kExitSegment = 3;
constexpr int kExitProtocol = 4;
constexpr int kExitStorageUnavailable = 5;

// Standalone: how often to look for the next client's segment. A renderer start takes far longer.
constexpr std::chrono::milliseconds kNextClientPoll{100};

std::atomic<bool> g_stop{false};
std::atomic<bool> g_print_stats{false};
static_assert(std::atomic<bool>::is_always_lock_free, "set from a signal handler");

// Async-signal-safe: the handlers only store to lock-free atomics; the server loop does the work.
extern "C" void on_stop_signal(int) { g_stop.store(true, std::memory_order_relaxed); }
extern "C" void on_stats_signal(int) { g_print_stats.store(true, std::memory_order_relaxed); }

void install_stop_handlers() {
  struct sigaction sa {};
  sa.sa_handler = on_stop_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART: a futex wait returns at once and the loop sees the flag
  sigaction(SIGTERM, &sa, nullptr);
  sigaction(SIGINT, &sa, nullptr);
  struct sigaction st {};
  st.sa_handler = on_stats_signal;
  sigemptyset(&st.sa_mask);
  st.sa_flags = 0;  // no SA_RESTART either: the idle futex wait returns and the loop prints at once
  sigaction(SIGUSR1, &st, nullptr);
}

// Who a segment belongs to: the same name reappears for the next renderer with a new epoch and owner.
struct ClientId {
  uint64_t epoch = 0;
  uint32_t pid = 0;
  uint64_t start_time = 0;
  bool operator==(const ClientId&) const = default;
};

ClientId client_of(const texstream::Segment& segment) {
  return {segment.header().epoch, segment.renderer_block().pid, segment.renderer_block().start_time};
}

// Standalone: waits until a segment named `name` exists whose renderer is alive and is not `previous`.
// Returns nullptr when stopped first.
std::unique_ptr<texstream::Segment> wait_for_next_client(const std::string& name, const ClientId& previous) {
  spdlog::info("waiting for the next renderer on segment '{}'", name);
  while (!g_stop.load(std::memory_order_relaxed)) {
    if (g_print_stats.exchange(false, std::memory_order_relaxed)) spdlog::info("statistics: no client attached");
    texstream::Result<std::unique_ptr<texstream::Segment>> segment = texstream::Segment::open(name);
    if (segment.ok()) {
      const ClientId id = client_of(**segment);
      if (!(id == previous) && texstream::process_alive(static_cast<int>(id.pid), id.start_time)) {
        return std::move(segment).value();
      }
    }
    std::this_thread::sleep_for(kNextClientPoll);  // a signal cuts it short; the loop then sees g_stop
  }
  return nullptr;
}

// A standalone server that found its segment held by another server: waits until the pid word is 0 again
// (nullopt: claim it now), the renderer is gone (kRendererDead) or we are told to stop (kStopped).
std::optional<texstream::server::RunOutcome> wait_until_free(const texstream::Segment& segment) {
  const ClientId renderer = client_of(segment);
  while (!g_stop.load(std::memory_order_relaxed)) {
    if (!texstream::process_alive(static_cast<int>(renderer.pid), renderer.start_time)) {
      return texstream::server::RunOutcome::kRendererDead;
    }
    if (segment.server_block().pid.v.load(std::memory_order_acquire) == 0) return std::nullopt;
    std::this_thread::sleep_for(kNextClientPoll);  // a signal cuts it short; the loop then sees g_stop
  }
  return texstream::server::RunOutcome::kStopped;
}

void setup_logging(texstream::LogLevel level) {
  auto logger = spdlog::stderr_color_mt("server");
  logger->set_pattern("[%H:%M:%S.%e] [server] [%l] %v");
  logger->set_level(spdlog::level::from_str(std::string(texstream::choice_name(level))));  // names are spdlog's
  spdlog::set_default_logger(logger);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"texstream-server: reads texture mips and hands them to texstream-render in shared memory"};
  std::string segment_name;
  std::string scene_dir;
  std::string config_file;
  std::vector<std::string> overrides;
  bool spawned = false;
  app.add_option("--segment", segment_name, "Shared-memory segment created by the renderer")->required();
  app.add_option("--scene", scene_dir, "Scene folder (overrides scene.dir)");
  app.add_option("--config", config_file, "TOML configuration file")->check(CLI::ExistingFile);
  app.add_option("--set", overrides, "Override one key: part.key=value (repeatable)");
  app.add_flag("--spawned", spawned, "Started by the renderer: die with it");
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return kExitBadArguments;
  }

  if (std::optional<std::string> problem = texstream::segment_name_problem(segment_name)) {
    fprintf(stderr, "[server] --segment: %s\n", problem->c_str());
    return kExitBadArguments;
  }
  if (spawned) {
    // Die with the parent even if it is SIGKILLed. If the parent died before this call, the signal will
    // never come: then our parent is already someone else.
    const pid_t parent = getppid();
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent || parent == 1) return kExitOk;
  }

  if (!scene_dir.empty()) overrides.push_back("scene.dir=" + scene_dir);
  texstream::Result<texstream::Config> config = texstream::load_config(config_file, overrides);
  if (!config.ok()) {
    fprintf(stderr, "[server] configuration: %s\n", config.error().message.c_str());
    return kExitBadArguments;
  }
  setup_logging(config->server.log_level);
  install_stop_handlers();
  // Before any thread starts (they inherit it): woken by the renderer's doorbell, a SCHED_BATCH server does not
  // preempt the renderer's frame thread on its core (docs/design/syscalls.md, "The server's scheduling").
  if (config->server.batch_scheduling) {
    const sched_param none{};
    if (sched_setscheduler(0, SCHED_BATCH, &none) != 0) {
      spdlog::warn("server.batch_scheduling: sched_setscheduler(SCHED_BATCH) failed: {}", std::strerror(errno));
    }
  }
  // A RAM cache that cannot fit this machine (or the memory cgroup of a container) would be OOM-killed once
  // it filled, and again after every restart: refused here (the renderer checks the same before spawning).
  if (texstream::Status fits = texstream::check_server_memory(*config, texstream::read_memory_info()); !fits.ok()) {
    spdlog::error("{}", fits.error().message);
    return kExitBadArguments;
  }

  // The storage tiers ([storage]: origin, slow-storage emulation, disk cache) live as long as the process:
  // the disk cache's lock and index survive from one renderer to the next.
  auto stack = texstream::server::make_storage_stack(config->storage, config->scene.dir);
  if (!stack.ok()) {
    spdlog::error("{}", stack.error().message);
    return stack.error().code == texstream::ErrorCode::kPeerDead ? kExitStorageUnavailable : kExitBadArguments;
  }
  spdlog::info("storage: {}", (*stack)->describe());
  // The scene is read now, before any waiting: a standalone server given a wrong --scene (or an unreadable
  // texture table) says so at once instead of waiting for a renderer it could never serve.
  auto scene = texstream::server::Server::read_scene((*stack)->scene_dir);
  if (!scene.ok()) {
    spdlog::error("{}", scene.error().message);
    return kExitBadArguments;
  }
  // So are the page files scene.json names (its "ground"), for a standalone server: a missing or damaged one is
  // said now, not when the first renderer comes (Server::create opens them again for each renderer; a spawned
  // server gets there at once).
  if (!spawned) {
    texstream::server::ServerStats unused;
    auto pages = texstream::server::PageLoader::open((*stack)->scene_dir, (*stack)->storage(), unused);
    if (!pages.ok()) {
      spdlog::error("{}", pages.error().message);
      return kExitBadArguments;
    }
  }
  // The first renderer's server takes this table; later ones map it again (the scene may have changed).
  texstream::server::SceneTextures first_scene = std::move(scene).value();
  texstream::Result<std::unique_ptr<texstream::Segment>> segment = texstream::Segment::open(segment_name);
  if (!segment.ok() && !spawned && segment.error().code == texstream::ErrorCode::kNotFound) {
    // Standalone and started before its renderer: wait for one to create the segment, as after a renderer
    // exits (before, it exited with status 3 and had to be started after the renderer).
    segment = texstream::Result<std::unique_ptr<texstream::Segment>>(wait_for_next_client(segment_name, ClientId{}));
    if (!*segment) return kExitOk;  // stopped while waiting
  }
  if (!segment.ok()) {
    spdlog::error("{}", segment.error().message);
    return kExitSegment;
  }
  std::unique_ptr<texstream::Segment> current = std::move(segment).value();
  for (;;) {
    // The cache pre-faults its whole budget (cache_arena.hpp): one that fits the limit but not what is free
    // now is lowered, with a warning, rather than taking the last of the memory (memory_info.hpp).
    texstream::ServerConfig server_config = config->server;
    std::string lowered;
    server_config.ram_cache_bytes = static_cast<int64_t>(texstream::server_cache_budget(
        static_cast<uint64_t>(server_config.ram_cache_bytes), texstream::read_memory_info(), &lowered));
    if (!lowered.empty()) spdlog::warn("{}", lowered);
    auto server = texstream::server::Server::create(*current, (*stack)->scene_dir, server_config, (*stack)->storage(),
                                                    std::move(first_scene));
    first_scene.reset();
    if (!server.ok() && server.error().code == texstream::ErrorCode::kProtocol && !spawned) {
      // Standalone, and this renderer reads another scene: it is refused (told through the segment, so that
      // it ends its run naming this server), and the server waits for the next renderer rather than exit: a
      // wrong renderer must not take down a server that others use.
      spdlog::error("{}; refused, waiting for the next renderer", server.error().message);
      current->server_block().refused_by.v.store(static_cast<uint32_t>(::getpid()), std::memory_order_release);
      const ClientId refused = client_of(*current);
      current.reset();
      current = wait_for_next_client(segment_name, refused);
      if (!current) return kExitOk;
      continue;
    }
    if (!server.ok()) {
      spdlog::error("{}", server.error().message);
      return kExitBadArguments;
    }
    spdlog::info(
        "serving segment '{}' (epoch {:016x}) from scene '{}' ({} workers, RAM cache {} bytes, {} policy, "
        "rate limit {} MB/s)",
        segment_name, current->header().epoch, config->scene.dir, config->server.worker_threads,
        server_config.ram_cache_bytes, texstream::choice_name(config->server.cache_policy),
        config->server.rate_limit_mb_s);
    texstream::server::RunOutcome outcome = (*server)->run(g_stop, &g_print_stats);
    if (outcome == texstream::server::RunOutcome::kSegmentBusy) {
      // Another server holds the segment (run() touched nothing). Spawned, this one is not needed. Standalone,
      // it waits for the segment to be free: the holder gone and the renderer's reset of its block done (pid
      // word 0); then a fresh Server claims it (this one's rings saw positions the reset has since zeroed).
      const uint32_t holder = (*server)->busy_holder();
      server.value().reset();
      if (spawned) {
        spdlog::error("segment '{}' is already served by texstream-server pid {}", segment_name, holder);
        return kExitSegment;
      }
      spdlog::warn("segment '{}' is served by texstream-server pid {}; waiting until it is free", segment_name, holder);
      const std::optional<texstream::server::RunOutcome> ended = wait_until_free(*current);
      if (!ended) continue;
      outcome = *ended;
    }
    if (outcome == texstream::server::RunOutcome::kPeerCorrupt) return kExitProtocol;
    if (outcome == texstream::server::RunOutcome::kStopped || spawned) return kExitOk;
    // Standalone and the renderer died: drop its state (server, mapping) and serve the next one.
    const ClientId previous = client_of(*current);
    server.value().reset();
    current.reset();
    current = wait_for_next_client(segment_name, previous);
    if (!current) return kExitOk;
  }
}
