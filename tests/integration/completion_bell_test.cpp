// The completion bell (doorbell.hpp) and the syscall accounting it is measured by (issue 29): a renderer
// thread waiting for completions is woken by the server's publish, across processes and under a ping-pong
// that loses no wake-up; and neither side makes a system call while the other is not waiting.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>

#include "../support/patience.hpp"
#include "../support/unique_name.hpp"
#include "texstream/common/syscall_count.hpp"
#include "texstream/protocol/doorbell.hpp"
#include "texstream/protocol/renderer_endpoint.hpp"
#include "texstream/protocol/segment.hpp"

namespace texstream {
namespace {

using test::unique_name;

using test::kHangAfter;
using test::promptly;

CompletionRecord record(uint32_t texture) {
  CompletionRecord c{};
  c.texture_id = texture;
  return c;
}

TEST(SyscallCount, EachThreadCountsIntoTheCounterItsRoleInstalled) {
  SyscallCounter server;
  const uint64_t process_before = process_syscalls().of(Syscall::kRead);
  std::thread t([&] {
    const SyscallAccount account(server);
    count_syscall(Syscall::kRead, 3);
    {
      SyscallCounter inner;
      const SyscallAccount nested(inner);
      count_syscall(Syscall::kRead);
      EXPECT_EQ(inner.total(), 1u);
    }
    count_syscall(Syscall::kOpen);  // the outer account again
  });
  t.join();
  count_syscall(Syscall::kRead);  // this thread installed none: the process's
  EXPECT_EQ(server.of(Syscall::kRead), 3u);
  EXPECT_EQ(server.of(Syscall::kOpen), 1u);
  EXPECT_EQ(server.total(), 4u);
  EXPECT_EQ(server.describe(), "4 (open 1, read 3)");
  EXPECT_EQ(process_syscalls().of(Syscall::kRead), process_before + 1);
}

TEST(CompletionBell, WakesARendererWaitingInAnotherProcess) {
  const std::string name = unique_name("bell");
  auto created = Segment::create(name, {16, 16, 1, 4096});
  ASSERT_TRUE(created.ok());
  Segment& seg = *created.value();
  RendererEndpoint renderer(seg);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {  // the server: publishes one completion after the renderer has gone to sleep
    auto opened = Segment::open(name);
    if (!opened.ok()) _exit(2);
    auto producer = opened.value()->completion_producer();
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    if (!producer.try_push(record(7))) _exit(3);
    CompletionBell(*opened.value()).ring();
    _exit(0);
  }
  const auto t0 = std::chrono::steady_clock::now();
  std::optional<CompletionRecord> got;
  while (!got && std::chrono::steady_clock::now() - t0 < kHangAfter) {
    renderer.wait_for_completions(std::chrono::duration_cast<std::chrono::microseconds>(kHangAfter));
    got = renderer.poll();
  }
  const auto waited = std::chrono::steady_clock::now() - t0;
  int status = 0;
  waitpid(child, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->texture_id, 7u);
  // Woken by the ring, not by the wait's own timeout.
  EXPECT_LT(waited, promptly(std::chrono::milliseconds(500)));
}

TEST(CompletionBell, NoSystemCallWhileNobodyWaitsOrACompletionIsThere) {
  auto created = Segment::create(unique_name("bell-quiet"), {16, 16, 1, 4096});
  ASSERT_TRUE(created.ok());
  Segment& seg = *created.value();
  RendererEndpoint renderer(seg);
  auto producer = seg.completion_producer();
  SyscallCounter counted;
  const SyscallAccount account(counted);
  CompletionBell server_side(seg);
  for (uint32_t i = 0; i < 1000; ++i) server_side.ring();  // nobody waits: no wake
  ASSERT_TRUE(producer.try_push(record(1)));
  // A completion already waits: the wait returns without the futex (a futex wait would be counted, and
  // would sleep for kHangAfter).
  renderer.wait_for_completions(std::chrono::duration_cast<std::chrono::microseconds>(kHangAfter));
  EXPECT_EQ(counted.total(), 0u) << counted.describe();
  EXPECT_EQ(seg.renderer_block().waiting.v.load(), 0u);
}

// Ping-pong: the server publishes completion k only after the renderer took k - 1, so every wake-up matters;
// a lost one would leave the renderer asleep for the whole (long) timeout. The Dekker handshake says none is.
TEST(CompletionBell, PingPongLosesNoWakeUp) {
  auto created = Segment::create(unique_name("bell-pingpong"), {16, 16, 1, 4096});
  ASSERT_TRUE(created.ok());
  Segment& seg = *created.value();
  RendererEndpoint renderer(seg);
  constexpr uint32_t kRounds = 20000;
  constexpr auto kLongWait = std::chrono::seconds(2);
  std::atomic<uint32_t> taken{0};
  std::thread server([&] {
    auto producer = seg.completion_producer();
    CompletionBell bell(seg);
    for (uint32_t k = 0; k < kRounds; ++k) {
      while (taken.load(std::memory_order_acquire) < k) std::this_thread::yield();
      while (!producer.try_push(record(k))) std::this_thread::yield();
      bell.ring();
    }
  });
  uint32_t slow_waits = 0;
  for (uint32_t k = 0; k < kRounds; ++k) {
    std::optional<CompletionRecord> c;
    while (!(c = renderer.poll())) {
      const auto t0 = std::chrono::steady_clock::now();
      renderer.wait_for_completions(kLongWait);
      if (std::chrono::steady_clock::now() - t0 >= kLongWait) ++slow_waits;
      if (slow_waits > 0) break;
    }
    if (slow_waits > 0) break;
    ASSERT_EQ(c->texture_id, k);
    taken.store(k + 1, std::memory_order_release);
  }
  taken.store(kRounds, std::memory_order_release);
  server.join();
  EXPECT_EQ(slow_waits, 0u) << "a wait ran into its timeout: a wake-up was lost";
}

}  // namespace
}  // namespace texstream
