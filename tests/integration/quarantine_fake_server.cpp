// A stand-in texstream-server for stream_crash_quarantine_test: it attaches to the segment named by
// `--segment` like the real server, answers every kLoad with kNotFound, and dies by a signal when asked for
// one chosen texture — after writing, as the real server's load workers do (worker_pool.cpp), the texture
// it is "loading" into ServerBlock::loading. Driven by the environment (the test sets it before the
// StreamClient spawns us):
//   TEXSTREAM_FAKE_CRASH_TEXTURE=N   die when a kLoad of texture N arrives (unset: never)
//   TEXSTREAM_FAKE_CRASH_SIGNAL=S    the signal to die by (default SIGSEGV)
//   TEXSTREAM_FAKE_BYSTANDER=M       also record texture M in a second loading word, on the first crash only
//   TEXSTREAM_FAKE_MARK=FILE         what "first" means across restarts: created at that crash
#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <thread>

#include "texstream/protocol/records.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/protocol/spsc_ring.hpp"

namespace {

std::optional<long> env_number(const char* name) {
  const char* v = std::getenv(name);
  if (v == nullptr || *v == '\0') return std::nullopt;
  return std::strtol(v, nullptr, 10);
}

[[noreturn]] void die(int signal) {
  const rlimit no_core{0, 0};
  ::setrlimit(RLIMIT_CORE, &no_core);  // a deliberate crash leaves no core file
  ::signal(signal, SIG_DFL);
  ::raise(signal);
  std::_Exit(99);  // not reached for a fatal signal
}

}  // namespace

int main(int argc, char** argv) {
  using namespace texstream;
  std::string segment_name;
  for (int i = 1; i + 1 < argc; ++i) {
    if (std::strcmp(argv[i], "--segment") == 0) segment_name = argv[i + 1];
  }
  if (segment_name.empty()) {
    std::fprintf(stderr, "quarantine_fake_server: no --segment\n");
    return 2;
  }
  const std::optional<long> crash_texture = env_number("TEXSTREAM_FAKE_CRASH_TEXTURE");
  const int crash_signal = static_cast<int>(env_number("TEXSTREAM_FAKE_CRASH_SIGNAL").value_or(SIGSEGV));
  const std::optional<long> bystander = env_number("TEXSTREAM_FAKE_BYSTANDER");
  // Loading this texture hangs the server (no heartbeat, nothing answered) until it is killed.
  const std::optional<long> hang_texture = env_number("TEXSTREAM_FAKE_HANG_TEXTURE");
  // Loading this texture stops the server (SIGSTOP on itself, as texstream-chaos or a debugger would).
  const std::optional<long> stop_texture = env_number("TEXSTREAM_FAKE_STOP_TEXTURE");
  const char* mark = std::getenv("TEXSTREAM_FAKE_MARK");

  auto opened = Segment::open(segment_name);
  if (!opened.ok()) {
    std::fprintf(stderr, "quarantine_fake_server: %s\n", opened.error().message.c_str());
    return 2;
  }
  Segment& seg = **opened;
  ServerBlock& block = seg.server_block();
  SpscRingConsumer<RequestRecord> requests = seg.request_consumer();
  SpscRingProducer<CompletionRecord> completions = seg.completion_producer();
  block.pid.v.store(static_cast<uint32_t>(::getpid()), std::memory_order_relaxed);
  block.attached.v.store(1, std::memory_order_release);

  const pid_t parent = ::getppid();
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (::getppid() == parent && std::chrono::steady_clock::now() < give_up) {
    block.heartbeat.v.fetch_add(1, std::memory_order_relaxed);
    while (std::optional<RequestRecord> r = requests.try_pop()) {
      if (r->kind != static_cast<uint32_t>(RequestKind::kLoad)) continue;
      if (stop_texture && r->texture_id == static_cast<uint32_t>(*stop_texture)) {
        block.loading[0].v.store(r->texture_id + 1, std::memory_order_relaxed);
        ::raise(SIGSTOP);
      }
      if (hang_texture && r->texture_id == static_cast<uint32_t>(*hang_texture)) {
        block.loading[0].v.store(r->texture_id + 1, std::memory_order_relaxed);
        while (::getppid() == parent && std::chrono::steady_clock::now() < give_up) {
          std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        return 0;
      }
      if (crash_texture && r->texture_id == static_cast<uint32_t>(*crash_texture)) {
        block.loading[0].v.store(r->texture_id + 1, std::memory_order_relaxed);
        if (bystander && mark != nullptr && !std::filesystem::exists(mark)) {
          std::ofstream{mark};
          block.loading[1].v.store(static_cast<uint32_t>(*bystander) + 1, std::memory_order_relaxed);
        }
        die(crash_signal);
      }
      CompletionRecord c{};
      c.status = static_cast<uint32_t>(CompletionStatus::kNotFound);
      c.request_kind = static_cast<uint32_t>(RequestKind::kLoad);
      c.slot = kNoSlot;
      c.texture_id = r->texture_id;
      c.mip_level = r->mip_level;
      c.generation = r->generation;
      while (!completions.try_push(c)) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  block.attached.v.store(0, std::memory_order_release);
  return 0;
}
