// texstream-server: serves one renderer through the shared segment the renderer created.
//
//   texstream-server --segment NAME --scene DIR [--config FILE] [--set part.key=value]... [--spawned]
//
// Exit codes: 0 stopped (SIGTERM/SIGINT) or the renderer exited; 2 bad arguments, configuration or scene;
// 3 the segment cannot be opened or its header does not match this build (the message names the field);
// 4 the renderer broke the ring protocol.
#include <signal.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <string>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/server/posix_storage.hpp"
#include "texstream/server/server.hpp"

namespace {

constexpr int kExitOk = 0;
constexpr int kExitBadArguments = 2;
constexpr int kExitSegment = 3;
constexpr int kExitProtocol = 4;

std::atomic<bool> g_stop{false};
static_assert(std::atomic<bool>::is_always_lock_free, "set from a signal handler");

extern "C" void on_stop_signal(int) { g_stop.store(true, std::memory_order_relaxed); }

void install_stop_handlers() {
  struct sigaction sa {};
  sa.sa_handler = on_stop_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART: a futex wait returns at once and the loop sees the flag
  sigaction(SIGTERM, &sa, nullptr);
  sigaction(SIGINT, &sa, nullptr);
}

void setup_logging(const std::string& level) {
  auto logger = spdlog::stderr_color_mt("server");
  logger->set_pattern("[%H:%M:%S.%e] [server] [%l] %v");
  logger->set_level(spdlog::level::from_str(level));
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

  texstream::Result<std::unique_ptr<texstream::Segment>> segment = texstream::Segment::open(segment_name);
  if (!segment.ok()) {
    spdlog::error("{}", segment.error().message);
    return kExitSegment;
  }
  texstream::server::PosixStorage storage;
  auto server = texstream::server::Server::create(**segment, config->scene.dir, config->server, storage);
  if (!server.ok()) {
    spdlog::error("{}", server.error().message);
    return kExitBadArguments;
  }
  spdlog::info("serving segment '{}' from scene '{}' ({} workers, RAM cache {} bytes)", segment_name,
               config->scene.dir, config->server.worker_threads, config->server.ram_cache_bytes);
  const texstream::server::RunOutcome outcome = (*server)->run(g_stop);
  switch (outcome) {
    case texstream::server::RunOutcome::kStopped: return kExitOk;
    // Standalone mode does not yet wait for a next client: it exits like a spawned server.
    case texstream::server::RunOutcome::kRendererDead: return kExitOk;
    case texstream::server::RunOutcome::kPeerCorrupt: return kExitProtocol;
  }
  return kExitOk;
}
