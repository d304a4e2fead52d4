// Named kill points (texture_server fault_point.hpp): TEXSTREAM_FAULT kills a process the N-th time it
// passes a point, TEXSTREAM_FAULT_ARM kills it at the next pass after texstream-chaos wrote the point's name
// into the arm file. Each case runs in a forked child (the environment is read once per process).
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <thread>

#include "../support/patience.hpp"
#include "chaos_test_support.hpp"
#include "texstream/protocol/spsc_ring.hpp"
#include "texstream/server/support/fault_point.hpp"

namespace texstream::server {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

TEST(FaultPlan, ParsesPointsAndPasses) {
  auto p = parse_fault_plan("slot_write,eviction@7");
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_EQ(p->die_on_pass[static_cast<int>(FaultPoint::kSlotWrite)], 1u);
  EXPECT_EQ(p->die_on_pass[static_cast<int>(FaultPoint::kEviction)], 7u);
  EXPECT_EQ(p->die_on_pass[static_cast<int>(FaultPoint::kBeforeCompletion)], 0u);
  for (const char* bad : {"", "slot_writes", "eviction@0", "eviction@", "eviction@-3", "eviction@5x",
                          "after_ring_push,", "slot_write,,eviction"}) {
    const auto r = parse_fault_plan(bad);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_NE(r.error().message.find("TEXSTREAM_FAULT"), std::string::npos) << r.error().message;
  }
  for (uint32_t i = 0; i < kFaultPointCount; ++i) {
    const auto point = static_cast<FaultPoint>(i);
    EXPECT_EQ(fault_point_from_string(to_string(point)), point);
  }
}

// Runs `body` in a forked child with `env` set; returns its wait status. This process itself never passes a
// point: its one-time read of the environment would be inherited by the children.
template <class Body>
int in_child(const char* name, const std::string& value, Body body) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::setenv(name, value.c_str(), 1);
    body();
    std::_Exit(0);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  return status;
}

TEST(FaultPoint, DiesOnTheNthPassOfItsPointOnly) {
  const fs::path marker = fs::temp_directory_path() / chaos_test::unique("fault-passes");
  const int status = in_child("TEXSTREAM_FAULT", "before_completion@3", [&] {
    for (int i = 0; i < 10; ++i) fault_point(FaultPoint::kSlotWrite);  // another point: no effect
    for (int i = 1; i <= 5; ++i) {
      std::ofstream(marker, std::ios::trunc) << i;
      fault_point(FaultPoint::kBeforeCompletion);
    }
  });
  ASSERT_TRUE(WIFSIGNALED(status)) << "exited with " << WEXITSTATUS(status);
  EXPECT_EQ(WTERMSIG(status), SIGKILL);
  std::ifstream in(marker);
  int passes = 0;
  in >> passes;
  EXPECT_EQ(passes, 3);
  fs::remove(marker);
}

TEST(FaultPoint, MidRingPushDiesWithTheRecordHalfWrittenAndUnpublished) {
  // The ring lives in a shared anonymous mapping so the parent sees what the killed child left in it.
  struct Shared {
    RingControl control;
    std::array<uint64_t, 4> records[4];
  };
  void* mem = ::mmap(nullptr, sizeof(Shared), PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
  ASSERT_NE(mem, MAP_FAILED);
  auto* shared = new (mem) Shared{};
  const int status = in_child("TEXSTREAM_FAULT", "mid_ring_push@2", [&] {
    SpscRingProducer<std::array<uint64_t, 4>> ring(&shared->control, shared->records, 4);
    if (fault_injection_enabled()) ring.set_mid_push_hook([] { fault_point(FaultPoint::kMidRingPush); });
    ring.try_push({1, 1, 1, 1});
    ring.try_push({2, 2, 2, 2});  // dies halfway through this one
    ring.try_push({3, 3, 3, 3});
  });
  ASSERT_TRUE(WIFSIGNALED(status)) << "exited with " << WEXITSTATUS(status);
  EXPECT_EQ(WTERMSIG(status), SIGKILL);
  EXPECT_EQ(shared->control.write_pos.v.load(), 1u) << "the torn record was published";
  EXPECT_EQ(shared->records[0], (std::array<uint64_t, 4>{1, 1, 1, 1}));
  EXPECT_EQ(shared->records[1], (std::array<uint64_t, 4>{2, 2, 0, 0})) << "not killed halfway through the copy";
  // A consumer sees exactly the one published record.
  SpscRingConsumer<std::array<uint64_t, 4>> consumer(&shared->control, shared->records, 4);
  EXPECT_TRUE(consumer.try_pop().has_value());
  EXPECT_FALSE(consumer.try_pop().has_value());
  ::munmap(mem, sizeof(Shared));
}

TEST(FaultPoint, CopyIntoSlotDiesHalfway) {
  std::vector<char> src(1000, 'x');
  const fs::path out = fs::temp_directory_path() / chaos_test::unique("fault-slot");
  const int status = in_child("TEXSTREAM_FAULT", "slot_write", [&] {
    std::vector<char> dst(src.size(), '.');
    copy_into_slot(dst.data(), src.data(), src.size());
    std::ofstream(out) << "copied";  // not reached
  });
  ASSERT_TRUE(WIFSIGNALED(status));
  EXPECT_EQ(WTERMSIG(status), SIGKILL);
  EXPECT_FALSE(fs::exists(out)) << "the copy went on past the point";
  // Without the point the copy completes (exit 0), also of nothing.
  const int clean = in_child("TEXSTREAM_FAULT_UNRELATED", "1", [&] {
    std::vector<char> dst(src.size(), '.');
    copy_into_slot(dst.data(), src.data(), src.size());
    copy_into_slot(nullptr, nullptr, 0);
    std::_Exit(dst == src ? 0 : 1);
  });
  ASSERT_TRUE(WIFEXITED(clean));
  EXPECT_EQ(WEXITSTATUS(clean), 0);
}

TEST(FaultPoint, ArmFileKillsAtTheNextPassAndIsClaimed) {
  const fs::path arm = fs::temp_directory_path() / chaos_test::unique("fault-arm");
  const fs::path marker = fs::temp_directory_path() / chaos_test::unique("fault-arm-marker");
  // Fork while this process has one thread only, and write the arm file from the parent afterwards: a
  // writer thread alive at fork() time could hold the allocator's lock (ASan's did), and the child's watcher
  // thread then blocks on it forever.
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::setenv("TEXSTREAM_FAULT_ARM", arm.c_str(), 1);
    const auto t0 = std::chrono::steady_clock::now();
    while (std::chrono::steady_clock::now() - t0 < test::kHangAfter) {
      fault_point(FaultPoint::kSlotWrite);
      if (std::chrono::steady_clock::now() - t0 < 50ms) std::ofstream(marker) << "early";
      fault_point(FaultPoint::kEviction);
      std::this_thread::sleep_for(1ms);
    }
    std::_Exit(0);
  }
  ASSERT_GT(pid, 0);
  std::this_thread::sleep_for(100ms);  // the child is passing points by then: nothing may fire before
  {
    const fs::path tmp = arm.string() + ".tmp";
    std::ofstream(tmp) << "eviction\n";
    fs::rename(tmp, arm);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status)) << "not killed within " << test::kHangAfter.count() << " s of arming";
  EXPECT_EQ(WTERMSIG(status), SIGKILL);
  EXPECT_FALSE(fs::exists(arm)) << "the arm file must be claimed";
  EXPECT_TRUE(fs::exists(marker)) << "it must not have died before the arm file appeared";
  std::error_code ec;
  fs::remove(marker, ec);
  for (const auto& e : fs::directory_iterator(arm.parent_path()))
    if (e.path().filename().string().rfind(arm.filename().string(), 0) == 0) fs::remove(e.path(), ec);
}

}  // namespace
}  // namespace texstream::server
