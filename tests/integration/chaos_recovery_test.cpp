// Issue 9, recovery with the real texstream-server: death told promptly by the pidfd, a hung (SIGSTOPped)
// server told by the heartbeat watchdog after protocol.heartbeat_timeout_ms, in-flight requests lost and
// their slots reclaimed, the restarted server answering the re-sent requests, a restart storm followed by
// normal streaming, and a server that exits when its renderer is SIGKILLed. Bounds: ../support/patience.hpp.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <thread>

#include "../support/patience.hpp"
#include "chaos_test_support.hpp"
#include "texstream/protocol/liveness.hpp"
#include "texstream/stream/stream_client.hpp"

namespace texstream {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;
using chaos_test::SmallScene;
using test::kHangAfter;
using test::promptly;
namespace fs = std::filesystem;

class CountingSink : public stream::MipSink {
 public:
  explicit CountingSink(const SmallScene& s) : scene_(s) {}
  std::span<std::byte> reserve(TextureId, MipLevel, uint64_t bytes) override {
    buffer_.assign(bytes, std::byte{0});
    return buffer_;
  }
  void commit(TextureId t, MipLevel m, std::span<std::byte> data) override {
    const auto& tex = scene_.textures[t.value];
    const auto f = static_cast<TexelFormat>(tex.format);
    const auto& file = scene_.files.at(t.value);
    const uint64_t off = scene::dds_mip_offset(f, tex.width, tex.height, m.value);
    EXPECT_TRUE(std::equal(data.begin(), data.end(), file.begin() + static_cast<std::ptrdiff_t>(off)))
        << "texture " << t.value << " mip " << m.value;
    ++commits;
  }
  void reject(TextureId t, MipLevel m, std::span<std::byte>) override {
    ADD_FAILURE() << "rejected texture " << t.value << " mip " << m.value;
  }
  void failed(TextureId, MipLevel, CompletionStatus s) override {
    if (s == CompletionStatus::kCancelled) {
      ++cancelled;
    } else {
      ++other_failures;
    }
  }
  int commits = 0, cancelled = 0, other_failures = 0;

 private:
  const SmallScene& scene_;
  std::vector<std::byte> buffer_;
};

struct Rig {
  SmallScene scene{8};
  std::unique_ptr<stream::StreamClient> client;
  CountingSink sink{scene};

  // Only the watchdog test keeps the default heartbeat timeout: elsewhere a server starved of CPU on a busy
  // machine must not be taken for a hung one (an extra death).
  explicit Rig(const std::string& segment, double heartbeat_timeout_ms = 10 * Config{}.protocol.heartbeat_timeout_ms) {
    const auto server = chaos_test::find_server();
    if (server.empty()) return;
    Config config;
    config.protocol.segment_name = segment;
    config.protocol.heartbeat_timeout_ms = heartbeat_timeout_ms;
    config.server.executable = server.string();
    config.scene.dir = scene.dir.string();
    auto c = stream::StreamClient::start(config, scene.shapes(), scene.dir, "", {"server.log_level=warn"}, {});
    EXPECT_TRUE(c.ok()) << (c.ok() ? "" : c.error().message);
    if (c.ok()) client = std::move(*c);
  }
  bool attached() { return client->segment().server_block().attached.v.load() == 1; }
  // Polls every 1 ms until `done` or `timeout`; returns the time it took (timeout if never).
  Clock::duration pump(const std::function<bool()>& done, Clock::duration timeout) {
    const auto t0 = Clock::now();
    while (!done() && Clock::now() - t0 < timeout) {
      client->poll(sink, 64);
      std::this_thread::sleep_for(1ms);
    }
    return Clock::now() - t0;
  }
  int request_all_mips(uint32_t texture) {
    int sent = 0;
    for (uint32_t m = 0; m < scene.textures[texture].mip_count; ++m)
      sent += client->request(TextureId(texture), MipLevel(m), 1.0f) ? 1 : 0;
    return sent;
  }
};

// What the hung-server test allows beyond protocol.heartbeat_timeout_ms: one heartbeat period, a poll and the
// reap (100 ms on a quiet machine; told after 1504.7 ms against 1400 + 100 once in CI's tsan stage). 1 s still
// tells the timeout from the startup grace or a second timeout (2 x 1400 ms).
constexpr auto kWatchdogSlack = promptly(100ms);

double ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

TEST(ChaosRecovery, DeathIsToldPromptlyAndTheRestartedServerAnswersTheLostRequests) {
  Rig rig(chaos_test::unique("death"));
  ASSERT_TRUE(rig.client) << "texstream-server not built";
  ASSERT_LT(rig.pump([&] { return rig.attached(); }, kHangAfter), kHangAfter) << "server never attached";
  const int first_pid = rig.client->server_pid();

  // Stop it so that the requests are surely in flight when it dies.
  ASSERT_EQ(::kill(first_pid, SIGSTOP), 0);
  rig.client->begin_cycle();
  const int sent = rig.request_all_mips(0) + rig.request_all_mips(1);
  ASSERT_GT(sent, 0);
  ASSERT_EQ(rig.client->stats().in_flight, static_cast<uint64_t>(sent));
  ASSERT_EQ(::kill(first_pid, SIGKILL), 0);
  const auto told = rig.pump([&] { return rig.client->stats().server_deaths == 1; }, kHangAfter);
  std::printf("server death told after %.2f ms\n", ms(told));
  EXPECT_LT(told, promptly(100ms)) << "the pidfd tells a death within 100 ms on a quiet machine";

  stream::StreamStats st = rig.client->stats();
  EXPECT_EQ(st.requests_lost, static_cast<uint64_t>(sent));
  EXPECT_EQ(st.in_flight, 0u);
  EXPECT_EQ(st.slots_held, 0u);
  EXPECT_EQ(rig.sink.cancelled, sent);
  EXPECT_EQ(st.server_crashes, 0u) << "an attached server killed from outside is not a crash";

  // The restart (first_delay 50 ms), then the same requests again: answered within the client's recovery
  // deadline (lost_answered_in_time).
  ASSERT_LT(rig.pump([&] { return rig.client->server_pid() > 0 && rig.attached(); }, kHangAfter), kHangAfter);
  EXPECT_NE(rig.client->server_pid(), first_pid);
  rig.client->begin_cycle();
  ASSERT_EQ(rig.request_all_mips(0) + rig.request_all_mips(1), sent);
  const auto answered = rig.pump([&] { return rig.client->stats().in_flight == 0; }, kHangAfter);
  std::printf("re-sent requests answered after %.2f ms\n", ms(answered));
  st = rig.client->stats();
  EXPECT_EQ(rig.sink.commits, sent);
  EXPECT_EQ(st.lost_resent, static_cast<uint64_t>(sent));
  EXPECT_EQ(st.lost_answered_in_time, static_cast<uint64_t>(sent));
  EXPECT_EQ(st.unserved_after_restart, 0u);
  EXPECT_EQ(st.protocol_errors, 0u);
}

TEST(ChaosRecovery, AStoppedServerIsKilledByTheWatchdogWithinTheHeartbeatTimeout) {
  Rig rig(chaos_test::unique("hang"), Config{}.protocol.heartbeat_timeout_ms);
  ASSERT_TRUE(rig.client) << "texstream-server not built";
  ASSERT_LT(rig.pump([&] { return rig.attached(); }, kHangAfter), kHangAfter);
  const int pid = rig.client->server_pid();
  ASSERT_EQ(::kill(pid, SIGSTOP), 0);
  const auto stopped_at = Clock::now();
  rig.client->begin_cycle();
  ASSERT_GT(rig.request_all_mips(2), 0);
  rig.pump([&] { return rig.client->stats().server_deaths == 1; }, kHangAfter);
  const auto told = Clock::now() - stopped_at;
  std::printf("hung server told after %.1f ms (protocol.heartbeat_timeout_ms = %.0f)\n", ms(told),
              Config{}.protocol.heartbeat_timeout_ms);
  ASSERT_EQ(rig.client->stats().server_deaths, 1u);
  // The watchdog fires once the heartbeat has not moved for the timeout; one poll (1 ms here) and the
  // reap follow. kWatchdogSlack covers the server's heartbeat period (server.idle_wait_ms = 20 ms) and scheduling.
  EXPECT_LT(told,
            std::chrono::milliseconds(static_cast<int64_t>(Config{}.protocol.heartbeat_timeout_ms)) + kWatchdogSlack);
  EXPECT_GT(told, std::chrono::milliseconds(static_cast<int64_t>(Config{}.protocol.heartbeat_timeout_ms)) - 100ms)
      << "killed before the heartbeat timeout";
  EXPECT_EQ(rig.client->stats().server_crashes, 1u) << "a hung server is a crash";
  EXPECT_EQ(rig.client->stats().slots_held, 0u);
  ASSERT_LT(rig.pump([&] { return rig.client->server_pid() > 0 && rig.attached(); }, kHangAfter), kHangAfter);
}

TEST(ChaosRecovery, ARestartStormEndsInNormalStreaming) {
  Rig rig(chaos_test::unique("storm"));
  ASSERT_TRUE(rig.client) << "texstream-server not built";
  // Issue 9: 100 kills (~15 s on a quiet machine, docs/faults.md; the time is printed and bounded so that a
  // stalled restart shows); TEXSTREAM_STORM_KILLS changes the count.
  const char* env = std::getenv("TEXSTREAM_STORM_KILLS");
  const int kKills = env != nullptr && std::atoi(env) > 0 ? std::atoi(env) : 100;
  const auto storm_start = Clock::now();
  for (int k = 0; k < kKills; ++k) {
    ASSERT_LT(rig.pump([&] { return rig.client->server_pid() > 0 && rig.attached(); }, kHangAfter), kHangAfter)
        << "kill " << k;
    rig.client->begin_cycle();
    (void)rig.request_all_mips(static_cast<uint32_t>(k % 8));
    ASSERT_EQ(::kill(rig.client->server_pid(), SIGKILL), 0);
    rig.pump([&] { return rig.client->stats().server_deaths == static_cast<uint64_t>(k + 1); }, kHangAfter);
  }
  const auto after_storm = Clock::now();
  std::printf("storm: %d SIGKILLs in %.1f s\n", kKills,
              std::chrono::duration<double>(after_storm - storm_start).count());
  EXPECT_LT(after_storm - storm_start, promptly(150ms) * kKills);
  const int before = rig.sink.commits;
  auto streaming = [&] {
    if (rig.client->stats().in_flight == 0) {
      rig.client->begin_cycle();
      for (uint32_t t = 0; t < 8; ++t) (void)rig.request_all_mips(t);
    }
    return rig.sink.commits > before + 20;
  };
  rig.pump(streaming, kHangAfter);
  const auto took = Clock::now() - after_storm;
  std::printf("normal streaming %.1f ms after a storm of %d kills\n", ms(took), kKills);
  EXPECT_LT(took, promptly(500ms)) << "streaming resumes within 500 ms of the last kill on a quiet machine";
  const stream::StreamStats st = rig.client->stats();
  EXPECT_EQ(st.server_deaths, static_cast<uint64_t>(kKills));
  EXPECT_EQ(st.server_state, stream::StreamServerState::kRunning);
  EXPECT_EQ(st.protocol_errors, 0u);
  EXPECT_EQ(st.unserved_after_restart, 0u);
}

TEST(ChaosRecovery, TheServerExitsWhenItsRendererIsKilledAndTheStaleSegmentIsRemovedLater) {
  const auto server = chaos_test::find_server();
  ASSERT_FALSE(server.empty()) << "texstream-server not built";
  SmallScene scene(4);
  const std::string segment = chaos_test::unique("orphan");
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const pid_t renderer = ::fork();
  ASSERT_GE(renderer, 0);
  if (renderer == 0) {
    // The stand-in renderer: a StreamClient that spawns the server, reports its pid, then waits to be killed.
    ::close(fds[0]);
    Config config;
    config.protocol.segment_name = segment;
    config.server.executable = server.string();
    auto c = stream::StreamClient::start(config, scene.shapes(), scene.dir, "", {"server.log_level=warn"}, {});
    int pid = -1;
    if (c.ok()) {
      CountingSink sink(scene);
      for (int i = 0; i < 10000 && (*c)->segment().server_block().attached.v.load() != 1; ++i) {
        (*c)->poll(sink, 8);
        ::usleep(1000);
      }
      pid = (*c)->server_pid();
    }
    (void)!::write(fds[1], &pid, sizeof pid);
    while (true) ::pause();
  }
  ::close(fds[1]);
  int server_pid = -1;
  ASSERT_EQ(::read(fds[0], &server_pid, sizeof server_pid), static_cast<ssize_t>(sizeof server_pid));
  ::close(fds[0]);
  ASSERT_GT(server_pid, 0);
  PidWatch watch(server_pid);
  ASSERT_TRUE(watch.valid());
  ::kill(renderer, SIGKILL);
  const auto t0 = Clock::now();
  while (!watch.dead() && Clock::now() - t0 < kHangAfter) std::this_thread::sleep_for(1ms);
  std::printf("server exited %.1f ms after its renderer was SIGKILLed\n", ms(Clock::now() - t0));
  EXPECT_TRUE(watch.dead());
  EXPECT_LT(Clock::now() - t0, promptly(100ms)) << "the server's pidfd on its renderer tells it at once";
  int status = 0;
  ::waitpid(renderer, &status, 0);

  // The killed renderer left its segment; the next renderer's start removes it (owner pid + start time dead).
  // A renderer started meanwhile by another test running in parallel sweeps it just the same, so it may be
  // gone already; it must be gone after ours.
  if (!fs::exists("/dev/shm/" + segment)) std::printf("the stale segment was already removed by another start\n");
  Config next;
  next.protocol.segment_name = chaos_test::unique("next");
  stream::StreamClientOptions external;
  external.spawn_server = false;
  auto c = stream::StreamClient::start(next, scene.shapes(), scene.dir, "", {}, external);
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_FALSE(fs::exists("/dev/shm/" + segment)) << "stale segment of a dead renderer left behind";
}

}  // namespace
}  // namespace texstream
