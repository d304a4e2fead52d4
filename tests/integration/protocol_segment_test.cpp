// The segment over real POSIX shared memory and real processes: create/open, a refused header, stale
// segments of killed owners removed, identity that survives pid reuse, a futex doorbell across processes,
// and rings whose peer is SIGKILLed mid-stream.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <string>
#include <thread>

#include <boost/interprocess/shared_memory_object.hpp>

#include "../support/forked_child.hpp"
#include "../support/patience.hpp"
#include "../support/unique_name.hpp"
#include "texstream/protocol/liveness.hpp"
#include "texstream/protocol/segment.hpp"

namespace texstream {
namespace {

using test::unique_name;

using test::kHangAfter;
using test::promptly;

// A child that creates the segment `name` and sleeps until killed: a renderer that can be SIGKILLed, leaving
// its segment behind. Its Segment is leaked on purpose: its destructor would remove the name.
pid_t fork_segment_owner(const std::string& name) {
  return test::fork_sleeper([&] {
    auto seg = Segment::create(name, {16, 16, 2, 4096});
    if (!seg.ok()) return false;
    (void)seg.value().release();
    return true;
  });
}

TEST(Segment, CreateOpenShareRingsAndSlots) {
  const std::string name = unique_name("basic");
  auto created = Segment::create(name, {64, 64, 4, 1 << 16});
  ASSERT_TRUE(created.ok()) << created.error().message;
  auto opened = Segment::open(name);
  ASSERT_TRUE(opened.ok()) << opened.error().message;
  Segment& r = *created.value();
  Segment& s = *opened.value();
  EXPECT_EQ(s.header().epoch, r.header().epoch);
  EXPECT_EQ(s.renderer_block().pid, static_cast<uint32_t>(getpid()));

  SpscRingProducer<RequestRecord> req = r.request_producer();
  SpscRingConsumer<RequestRecord> srv = s.request_consumer();
  RequestRecord rec{};
  rec.kind = static_cast<uint32_t>(RequestKind::kLoad);
  rec.texture_id = 42;
  ASSERT_TRUE(req.try_push(rec));
  auto got = srv.try_pop();
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->texture_id, 42u);

  std::memset(s.slot(3).data(), 0xab, 100);
  EXPECT_EQ(static_cast<unsigned char>(r.slot(3)[99]), 0xab);
  EXPECT_EQ(s.slot(3).size(), 1u << 16);

  // A second create with the same name must fail, not share.
  EXPECT_FALSE(Segment::create(name, {64, 64, 4, 1 << 16}).ok());
}

TEST(Segment, OpenRefusesAMismatchedHeaderNamingTheField) {
  const std::string name = unique_name("mismatch");
  auto created = Segment::create(name, {64, 64, 4, 1 << 16});
  ASSERT_TRUE(created.ok());
  // Simulate a peer built with another layout version by patching the mapped header.
  auto peer = Segment::open(name);
  ASSERT_TRUE(peer.ok());
  auto* raw = reinterpret_cast<SegmentHeader*>(peer.value()->slot(0).data() - peer.value()->header().slots_offset);
  raw->layout_version = kLayoutVersion + 1;
  auto refused = Segment::open(name);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("'layout_version'"), std::string::npos) << refused.error().message;
}

TEST(Segment, OpenOfAMissingSegmentFailsClearly) {
  auto r = Segment::open(unique_name("absent"));
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("absent"), std::string::npos);
}

TEST(Segment, StaleSegmentOfAKilledOwnerIsRemoved) {
  const std::string prefix = "texstream-test-stale-" + std::to_string(getpid()) + "-";
  const std::string name = prefix + "a";
  const pid_t child = fork_segment_owner(name);
  ASSERT_GT(child, 0);
  // While the owner lives, its segment is not stale.
  EXPECT_EQ(Segment::remove_stale(prefix), 0);
  EXPECT_TRUE(Segment::open(name).ok());
  kill(child, SIGKILL);
  waitpid(child, nullptr, 0);
  EXPECT_EQ(Segment::remove_stale(prefix), 1);
  EXPECT_FALSE(Segment::open(name).ok());
}

TEST(Segment, AChosenNameOfALiveRendererIsRefusedNamingItAndADeadOnesIsRemoved) {
  // protocol.segment_name: a renderer SIGKILLed left its segment behind, and every later renderer with the same
  // name failed with "File exists" (the start-up sweep covers only "texstream-" names).
  const std::string name = "ts-test-chosen-" + std::to_string(getpid());
  const pid_t child = fork_segment_owner(name);
  ASSERT_GT(child, 0);
  EXPECT_FALSE(Segment::remove_if_stale(name)) << "the owner lives";
  EXPECT_EQ(Segment::live_owner(name), static_cast<uint32_t>(child));
  auto second = Segment::create(name, {16, 16, 2, 4096});
  ASSERT_FALSE(second.ok());
  EXPECT_NE(second.error().message.find("belongs to a live renderer, pid " + std::to_string(child)), std::string::npos)
      << second.error().message;
  EXPECT_NE(second.error().message.find("protocol.segment_name"), std::string::npos) << second.error().message;
  kill(child, SIGKILL);
  waitpid(child, nullptr, 0);
  EXPECT_FALSE(Segment::live_owner(name));
  EXPECT_TRUE(Segment::remove_if_stale(name));
  EXPECT_FALSE(Segment::remove_if_stale(name)) << "gone already";
  auto third = Segment::create(name, {16, 16, 2, 4096});
  EXPECT_TRUE(third.ok()) << third.error().message;
}

TEST(Segment, ASegmentBeingCreatedIsNotTakenForStale) {
  // Another process between shm_open/truncate and `ready`: its segment has pid 0 and is not ready. A
  // concurrent remove_stale() (every renderer runs one at start) must leave it alone.
  const std::string prefix = "texstream-test-creating-" + std::to_string(getpid()) + "-";
  const std::string name = prefix + "a";
  boost::interprocess::shared_memory_object shm(boost::interprocess::create_only, name.c_str(),
                                                boost::interprocess::read_write);
  EXPECT_EQ(Segment::remove_stale(prefix), 0) << "an empty, just-created segment was removed";
  shm.truncate(static_cast<boost::interprocess::offset_t>(compute_layout({16, 16, 1, 4096}).total_bytes));
  EXPECT_EQ(Segment::remove_stale(prefix), 0) << "a sized but not yet ready segment was removed";
  EXPECT_TRUE(Segment::remove(name));
}

TEST(Segment, ASegmentLargerThanDevShmIsRefusedAtCreationNamingTheKeys) {
  // In a child with a mount namespace of its own and a 1 MiB tmpfs on /dev/shm (root only: skipped
  // otherwise). A segment that does not fit must fail create() with an error naming /dev/shm and the config
  // keys, and leave no object behind: before, truncate() succeeded (tmpfs files are sparse) and the first
  // write past the free space raised SIGBUS in whichever process made it, usually the server copying a mip.
  const test::ChildResult r = test::run_in_child([](const auto& finish) {
    if (!test::mount_private_tmpfs("/dev/shm", "1m")) {
      finish(std::string("no mount namespace here: ") + std::strerror(errno), test::kChildCannotRun);
    }
    const std::string name = unique_name("toolarge");
    auto small = Segment::create(name + "-small", {64, 64, 4, 1 << 16});  // ~0.3 MiB: fits
    if (!small.ok()) finish("a segment that fits was refused: " + small.error().message, 1);
    small.value().reset();
    auto big = Segment::create(name, {64, 64, 4, 1 << 20});  // ~4 MiB
    if (big.ok()) finish("a 4 MiB segment was created on a 1 MiB /dev/shm", 1);
    const std::string& m = big.error().message;
    if (m.find("/dev/shm") == std::string::npos || m.find("protocol.staging_slot_count") == std::string::npos ||
        m.find(name) == std::string::npos) {
      finish("the error does not name the segment, /dev/shm and the keys: " + m, 1);
    }
    if (Segment::open(name).ok()) finish("the refused segment was left behind", 1);
    finish(m, 0);
  });
  ASSERT_EQ(r.signal, 0) << "the child died by signal " << r.signal << " (SIGBUS is " << SIGBUS << ")";
  if (r.code == test::kChildCannotRun) GTEST_SKIP() << r.text;
  EXPECT_EQ(r.code, 0) << r.text;
  std::printf("  create() said: %s\n", r.text.c_str());
}

TEST(Liveness, IdentityIsPidPlusStartTime) {
  const auto mine = process_start_time(getpid());
  ASSERT_TRUE(mine.has_value());
  EXPECT_TRUE(process_alive(getpid(), *mine));
  // Same pid, another start time: a reused pid is not the same process.
  EXPECT_FALSE(process_alive(getpid(), *mine + 1));
  EXPECT_FALSE(process_alive(0, 0));
}

TEST(Liveness, PidfdTellsDeathPromptly) {
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    pause();
    _exit(0);
  }
  PidWatch watch(child);
  ASSERT_TRUE(watch.valid());
  EXPECT_FALSE(watch.dead());
  kill(child, SIGKILL);
  const auto t0 = std::chrono::steady_clock::now();
  while (!watch.dead() && std::chrono::steady_clock::now() - t0 < kHangAfter) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  const auto waited = std::chrono::steady_clock::now() - t0;
  EXPECT_TRUE(watch.dead());
  EXPECT_LT(waited, promptly(std::chrono::milliseconds(100))) << "DESIGN: death is told by the kernel within 100 ms";
  waitpid(child, nullptr, 0);
}

TEST(Liveness, FutexDoorbellWakesAnotherProcess) {
  const std::string name = unique_name("futex");
  auto created = Segment::create(name, {16, 16, 1, 4096});
  ASSERT_TRUE(created.ok());
  auto& bell = created.value()->renderer_block().doorbell;
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    auto seg = Segment::open(name);
    if (!seg.ok()) _exit(2);
    auto& b = seg.value()->renderer_block().doorbell;
    const auto t0 = std::chrono::steady_clock::now();
    while (b.v.load() == 0 && std::chrono::steady_clock::now() - t0 < kHangAfter) {
      futex_wait(b, 0, kHangAfter);
    }
    // Woken by the ring, not by the wait's own timeout.
    const auto waited = std::chrono::steady_clock::now() - t0;
    _exit(b.v.load() == 1 && waited < promptly(std::chrono::milliseconds(500)) ? 0 : 1);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  bell.v.fetch_add(1);
  futex_wake_all(bell);
  int status = 0;
  waitpid(child, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
}

TEST(Segment, ProducerKilledMidStreamLeavesOnlyWholeRecords) {
  const std::string name = unique_name("kill");
  auto created = Segment::create(name, {256, 256, 1, 4096});
  ASSERT_TRUE(created.ok());
  Segment& r = *created.value();
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    auto seg = Segment::open(name);
    if (!seg.ok()) _exit(2);
    SpscRingProducer<RequestRecord> p = seg.value()->request_producer();
    for (uint32_t i = 0;;) {
      RequestRecord rec{};
      rec.kind = static_cast<uint32_t>(RequestKind::kLoad);
      rec.texture_id = i;
      rec.generation = uint64_t{i} * 7 + 3;
      if (p.try_push(rec)) ++i;
    }
  }
  SpscRingConsumer<RequestRecord> c = r.request_consumer();
  uint32_t expected = 0, torn = 0;
  const auto t0 = std::chrono::steady_clock::now();
  bool killed = false;
  while (true) {
    // Mid-stream: after 300 ms and 1000 records (a busy machine may take longer to produce them).
    const auto running = std::chrono::steady_clock::now() - t0;
    if (!killed && ((running > std::chrono::milliseconds(300) && expected > 1000) || running > kHangAfter)) {
      kill(child, SIGKILL);
      waitpid(child, nullptr, 0);
      killed = true;
    }
    auto rec = c.try_pop();
    if (!rec) {
      if (killed) break;
      continue;
    }
    if (rec->texture_id != expected || rec->generation != uint64_t{expected} * 7 + 3) ++torn;
    ++expected;
  }
  EXPECT_GT(expected, 1000u);
  EXPECT_EQ(torn, 0u);
  EXPECT_EQ(c.error(), RingError::kNone);
}

}  // namespace
}  // namespace texstream
