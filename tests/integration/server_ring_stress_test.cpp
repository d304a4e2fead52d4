// The segment's SPSC rings across two real processes (fork): 10^7 records each way at once — the child
// produces requests and consumes completions, the parent the reverse — with nothing lost, duplicated,
// reordered or torn. Every record carries its sequence number in three places (generation, texture_id and a
// scrambled copy in the reserved words): a torn or stale copy breaks one of them.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <string>
#include <thread>

#include "../support/patience.hpp"
#include "texstream/protocol/segment.hpp"

namespace texstream {
namespace {

constexpr uint64_t kRecords = 10'000'000;
constexpr uint64_t kScramble = 0x9e3779b97f4a7c15ull;
// The child gives up (and fails) after this long; the parent kills it after a little more. A hang detector:
// 10^7 records each way take ~2 s in Release and ~10x that under TSan (its CI stage runs this test).
constexpr auto kDeadline = test::promptly(std::chrono::seconds(20));

RequestRecord make_request(uint64_t seq) {
  RequestRecord r{};
  r.kind = static_cast<uint32_t>(RequestKind::kLoad);
  r.texture_id = static_cast<uint32_t>(seq);
  r.generation = seq;
  r.reserved1[0] = seq * kScramble;
  r.reserved1[2] = ~seq;  // the record's last 8 bytes
  return r;
}

bool valid_request(const RequestRecord& r, uint64_t seq) {
  return r.generation == seq && r.texture_id == static_cast<uint32_t>(seq) && r.reserved1[0] == seq * kScramble &&
         r.reserved1[2] == ~seq;
}

CompletionRecord make_completion(uint64_t seq) {
  CompletionRecord c{};
  c.status = static_cast<uint32_t>(CompletionStatus::kOk);
  c.generation = seq;
  c.texture_id = static_cast<uint32_t>(seq >> 3);
  c.checksum = seq * kScramble;
  c.page_x = static_cast<uint32_t>(~seq);  // the record's last 8 bytes
  c.page_y = static_cast<uint32_t>(~seq >> 32);
  return c;
}

bool valid_completion(const CompletionRecord& c, uint64_t seq) {
  return c.generation == seq && c.texture_id == static_cast<uint32_t>(seq >> 3) && c.checksum == seq * kScramble &&
         c.page_x == static_cast<uint32_t>(~seq) && c.page_y == static_cast<uint32_t>(~seq >> 32);
}

// Pushes and pops until both counts reach kRecords. Returns an empty string or what went wrong.
template <class Out, class In, class Make, class Check>
std::string pump(SpscRingProducer<Out>& producer, SpscRingConsumer<In>& consumer, Make make, Check check) {
  uint64_t sent = 0, received = 0;
  const auto deadline = std::chrono::steady_clock::now() + kDeadline;
  uint32_t spins = 0;
  while (sent < kRecords || received < kRecords) {
    bool progress = false;
    // Bursts in both directions so neither ring stays full while the peer waits on the other one.
    for (int i = 0; i < 64 && sent < kRecords && producer.try_push(make(sent)); ++i, ++sent) progress = true;
    for (int i = 0; i < 64 && received < kRecords; ++i) {
      const std::optional<In> r = consumer.try_pop();
      if (!r) break;
      if (!check(*r, received)) return "record " + std::to_string(received) + " is wrong (lost, reordered or torn)";
      ++received;
      progress = true;
    }
    if (producer.error() != RingError::kNone || consumer.error() != RingError::kNone) return "ring protocol error";
    if (!progress && ++spins % 1024 == 0) {
      if (std::chrono::steady_clock::now() > deadline) {
        return "timed out at " + std::to_string(sent) + " sent, " + std::to_string(received) + " received";
      }
      std::this_thread::yield();  // 2 cores: let the peer run
    }
  }
  // Nothing extra may follow.
  if (consumer.try_pop()) return "a record beyond the last one";
  return {};
}

TEST(ServerRingStressTest, TenMillionRecordsEachWayAcrossTwoProcesses) {
  const std::string name = "texstream-ringstress-" + std::to_string(getpid());
  SegmentParams params;
  params.slot_count = 1;
  params.slot_bytes = 4096;
  auto seg = Segment::create(name, params);
  ASSERT_TRUE(seg.ok()) << seg.error().message;

  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    // Child: the renderer's side through its own mapping.
    auto mine = Segment::open(name);
    if (!mine.ok()) _exit(3);
    Segment& s = **mine;
    SpscRingProducer<RequestRecord> requests = s.request_producer();
    SpscRingConsumer<CompletionRecord> completions = s.completion_consumer();
    const std::string err = pump(requests, completions, make_request, valid_completion);
    if (!err.empty()) {
      std::fprintf(stderr, "child: %s\n", err.c_str());
      _exit(1);
    }
    _exit(0);
  }
  Segment& s = **seg;
  SpscRingProducer<CompletionRecord> completions = s.completion_producer();
  SpscRingConsumer<RequestRecord> requests = s.request_consumer();
  const auto t0 = std::chrono::steady_clock::now();
  const std::string err = pump(completions, requests, make_completion, valid_request);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(err, "");
  int status = 0;
  if (!err.empty()) kill(child, SIGKILL);
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status)) << "child died of signal " << WTERMSIG(status);
  EXPECT_EQ(WEXITSTATUS(status), 0) << "the child saw a wrong completion (see its stderr)";
  EXPECT_EQ(requests.position(), kRecords);
  EXPECT_EQ(completions.position(), kRecords);
  std::printf("%llu records each way in %.2f s (%.1f M records/s per direction)\n",
              static_cast<unsigned long long>(kRecords), seconds, static_cast<double>(kRecords) / seconds / 1e6);
}

}  // namespace
}  // namespace texstream
