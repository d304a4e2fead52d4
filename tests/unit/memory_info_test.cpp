// MemoryInfo from fake /proc and /sys trees (cgroup v1 and v2, nested limits, containers whose cgroup path is
// not mounted), and the two decisions made from it: a server that cannot fit is a configuration error naming
// server.ram_cache_bytes; a budget larger than what is free now is lowered, keeping a reserve.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "texstream/common/memory_info.hpp"

namespace texstream {
namespace {

namespace fs = std::filesystem;

constexpr uint64_t kMiB = 1ull << 20, kGiB = 1ull << 30;

class FakeRoots : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() / ("texstream-meminfo-" + std::to_string(getpid()) + "-" +
                                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(root_);
    write("proc/meminfo", "MemTotal:       24576000 kB\nMemFree:        20000000 kB\nMemAvailable:   22000000 kB\n");
  }
  void TearDown() override { fs::remove_all(root_); }
  void write(const std::string& rel, const std::string& text) {
    const fs::path p = root_ / rel;
    fs::create_directories(p.parent_path());
    std::ofstream(p) << text;
  }
  MemoryInfo read() const { return read_memory_info(root_ / "sys", root_ / "proc"); }
  fs::path root_;
};

TEST_F(FakeRoots, PhysicalMemoryWithoutACgroupLimit) {
  write("proc/self/cgroup", "0::/user.slice\n");
  write("sys/fs/cgroup/user.slice/memory.max", "max\n");
  const MemoryInfo m = read();
  EXPECT_EQ(m.limit, 24576000ull * 1024);
  EXPECT_EQ(m.available, 22000000ull * 1024);
  EXPECT_NE(m.limit_source.find("MemTotal"), std::string::npos) << m.limit_source;
}

TEST_F(FakeRoots, CgroupV2LimitOfAnAncestorAppliesAndItsRoomCountsReclaimableCacheAsFree) {
  write("proc/self/cgroup", "0::/docker/abc/inner\n");
  write("sys/fs/cgroup/docker/abc/inner/memory.max", "max\n");
  write("sys/fs/cgroup/docker/abc/memory.max", std::to_string(2 * kGiB) + "\n");
  write("sys/fs/cgroup/docker/abc/memory.current", std::to_string(1500 * kMiB) + "\n");
  write("sys/fs/cgroup/docker/abc/memory.stat", "anon 1000\ninactive_file " + std::to_string(500 * kMiB) + "\n");
  const MemoryInfo m = read();
  EXPECT_EQ(m.limit, 2 * kGiB);
  EXPECT_NE(m.limit_source.find("docker/abc/memory.max"), std::string::npos) << m.limit_source;
  EXPECT_EQ(m.available, 2 * kGiB - 1000 * kMiB);  // 1500 used, 500 of it reclaimable page cache
}

TEST_F(FakeRoots, CgroupV1LimitAndAContainerWhosePathIsNotMountedUsesTheMountRoot) {
  // Inside a container /proc/self/cgroup names the host's path; only the container's own cgroup is mounted.
  write("proc/self/cgroup", "9:name=systemd:/\n4:cpu,memory:/process_api/xyz\n0::/\n");
  write("sys/fs/cgroup/memory/memory.limit_in_bytes", std::to_string(1536 * kMiB) + "\n");
  write("sys/fs/cgroup/memory/memory.usage_in_bytes", std::to_string(600 * kMiB) + "\n");
  write("sys/fs/cgroup/memory/memory.stat", "cache 1\ntotal_inactive_file " + std::to_string(100 * kMiB) + "\n");
  const MemoryInfo m = read();
  EXPECT_EQ(m.limit, 1536 * kMiB);
  EXPECT_EQ(m.available, 1536 * kMiB - 500 * kMiB);
}

TEST_F(FakeRoots, V1NoLimitValueAndMalformedFilesAreIgnored) {
  write("proc/self/cgroup", "4:memory:/a\n");
  write("sys/fs/cgroup/memory/a/memory.limit_in_bytes", "9223372036854771712\n");
  write("sys/fs/cgroup/memory/memory.limit_in_bytes", "garbage\n");
  const MemoryInfo m = read();
  EXPECT_EQ(m.limit, 24576000ull * 1024);
  EXPECT_FALSE(cgroup_limit_bytes("max\n"));
  EXPECT_FALSE(cgroup_limit_bytes("-1\n"));
  EXPECT_FALSE(cgroup_limit_bytes("99999999999999999999999\n"));  // overflows: not a limit
  EXPECT_EQ(cgroup_limit_bytes("1610612736\n"), 1610612736u);
  EXPECT_FALSE(meminfo_bytes("MemTotal: 12 MB\n", "MemTotal"));
  EXPECT_FALSE(meminfo_bytes("MemTotalX: 12 kB\n", "MemTotal"));
}

TEST_F(FakeRoots, NothingReadableMeansUnknownAndChecksPass) {
  fs::remove_all(root_ / "proc");
  const MemoryInfo m = read();
  EXPECT_EQ(m.limit, UINT64_MAX);
  Config c;
  c.server.ram_cache_bytes = 1ll << 40;
  EXPECT_TRUE(check_server_memory(c, m).ok());
  EXPECT_EQ(server_cache_budget(1ull << 40, m), 1ull << 40);
}

TEST(ServerMemory, AServerThatCannotFitIsAConfigErrorNamingTheKeyAndTheLimit) {
  Config c;
  c.protocol.staging_slot_count = 32;
  c.protocol.staging_slot_bytes = static_cast<int64_t>(kMiB);  // 32 slots of 1 MiB
  MemoryInfo m{1536 * kMiB, "memory cgroup limit (/sys/fs/cgroup/x/memory.max)", 1400 * kMiB};
  c.server.ram_cache_bytes = static_cast<int64_t>(3 * kGiB);
  const Status s = check_server_memory(c, m);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(s.error().message.find("server.ram_cache_bytes"), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("1610612736"), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("/sys/fs/cgroup/x/memory.max"), std::string::npos) << s.error().message;
  // Exactly at the limit fits; one byte more does not (cache + 32 MiB staging + 64 MiB overhead).
  c.server.ram_cache_bytes = static_cast<int64_t>(1536 * kMiB - 32 * kMiB - kServerOverheadBytes);
  EXPECT_EQ(server_memory_bytes(c), 1536 * kMiB);
  EXPECT_TRUE(check_server_memory(c, m).ok());
  c.server.ram_cache_bytes += 1;
  EXPECT_FALSE(check_server_memory(c, m).ok());
}

TEST(ServerMemory, ABudgetLargerThanWhatIsFreeIsLoweredKeepingAReserve) {
  // 16 GiB limit: the reserve is an eighth, 2 GiB. 10 GiB free: at most 8 GiB for the cache.
  const MemoryInfo m{16 * kGiB, "physical memory", 10 * kGiB};
  std::string why;
  EXPECT_EQ(server_cache_budget(4 * kGiB, m, &why), 4 * kGiB);
  EXPECT_TRUE(why.empty());
  EXPECT_EQ(server_cache_budget(12 * kGiB, m, &why), 8 * kGiB);
  EXPECT_NE(why.find("server.ram_cache_bytes"), std::string::npos) << why;
  // A small machine keeps at least 256 MiB; nothing free beyond it leaves no cache at all.
  EXPECT_EQ(server_cache_budget(kGiB, MemoryInfo{kGiB, "physical memory", 300 * kMiB}), 44 * kMiB);
  EXPECT_EQ(server_cache_budget(kGiB, MemoryInfo{kGiB, "physical memory", 200 * kMiB}), 0u);
}

TEST(ServerMemory, ThisMachineReadsSomethingSensible) {
  const MemoryInfo m = read_memory_info();
  ASSERT_NE(m.limit, UINT64_MAX) << "no /proc/meminfo?";
  EXPECT_GT(m.limit, 64 * kMiB);
  EXPECT_LE(m.available, m.limit);
  EXPECT_GT(m.available, 0u);
}

}  // namespace
}  // namespace texstream
