// The real texstream-server executable against a segment this test (or a forked child) created: arguments
// and exit codes, one streamed mip, clean exit on SIGTERM, and exit when the segment's owner dies.
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "../support/patience.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/checksum.hpp"
#include "texstream/protocol/doorbell.hpp"
#include "texstream/protocol/liveness.hpp"
#include "texstream/protocol/segment.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using texstream::test::kHangAfter;

namespace texstream {
namespace {

const std::string kServer = std::string(TEXSTREAM_BIN_DIR) + "/texstream-server";

// Every child a test forks (servers and stand-in owners): TearDown kills those still running, so a failed
// assertion cannot leave a standalone server holding the test's output pipe open (ctest then waits for it
// until its timeout).
std::vector<pid_t> g_children;

// Kills and reaps the children of g_children that are still running. waitpid(WNOHANG) = 0 only for a child of
// ours that is running, so a reaped pid, even if reused by another process, is never signalled.
void reap_children() {
  for (const pid_t pid : g_children) {
    int status = 0;
    if (waitpid(pid, &status, WNOHANG) != 0) continue;
    kill(pid, SIGKILL);
    waitpid(pid, &status, 0);
  }
  g_children.clear();
}

// Starts the server with `args`; stdout/stderr stay the test's (its log lines show up in ctest output)
// unless `stderr_file` is given.
pid_t spawn_server(const std::vector<std::string>& args, const fs::path& stderr_file = {}) {
  std::vector<std::string> all{kServer};
  all.insert(all.end(), args.begin(), args.end());
  const pid_t pid = fork();
  if (pid == 0) {
    if (!stderr_file.empty()) {
      const int fd = open(stderr_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd >= 0) dup2(fd, 2);
    }
    std::vector<char*> argv;
    for (auto& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    execv(kServer.c_str(), argv.data());
    _exit(127);
  }
  if (pid > 0) g_children.push_back(pid);
  return pid;
}

// waitpid with a deadline: the exit status, or nullopt (the process is then killed and reaped).
std::optional<int> wait_exit(pid_t pid, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    int status = 0;
    const pid_t r = waitpid(pid, &status, WNOHANG);
    if (r == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    if (std::chrono::steady_clock::now() >= deadline) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      return std::nullopt;
    }
    std::this_thread::sleep_for(5ms);
  }
}

std::string read_text(const fs::path& file) {
  std::string out;
  if (FILE* f = std::fopen(file.c_str(), "rb")) {
    char buf[4096];
    size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) out.append(buf, n);
    std::fclose(f);
  }
  return out;
}

class ServerProcessTest : public ::testing::Test {
 protected:
  void SetUp() override {
    static int counter = 0;
    name_ = "texstream-srvproc-" + std::to_string(getpid()) + "-" + std::to_string(counter++);
    dir_ = fs::temp_directory_path() / name_;
    fs::create_directories(dir_);
    const scene::TextureRecord t{32, 32, full_mip_count(32, 32), uint32_t(TexelFormat::kRgba8)};
    ASSERT_TRUE(scene::write_texture_table(dir_, std::span(&t, 1)).ok());
    const auto header = scene::make_dds_header(TexelFormat::kRgba8, 32, 32, t.mip_count);
    payload_.resize(scene::dds_file_bytes(TexelFormat::kRgba8, 32, 32, t.mip_count) - scene::kDdsHeaderBytes);
    for (size_t i = 0; i < payload_.size(); ++i) payload_[i] = static_cast<std::byte>((i * 13 + 5) & 0xff);
    const fs::path path = scene::texture_path(dir_, TextureId(0));
    fs::create_directories(path.parent_path());
    std::ofstream f(path, std::ios::binary);
    f.write(reinterpret_cast<const char*>(header.data()), header.size());
    f.write(reinterpret_cast<const char*>(payload_.data()), static_cast<std::streamsize>(payload_.size()));
  }

  void TearDown() override {
    reap_children();
    Segment::remove(name_);  // a killed owner could not remove it
    fs::remove_all(dir_);
  }

  std::vector<std::string> server_args(bool spawned = false) {
    std::vector<std::string> a{"--segment", name_, "--scene", dir_.string(), "--set", "server.idle_wait_ms=5"};
    if (spawned) a.push_back("--spawned");
    return a;
  }

  // Plays the renderer on a mapping of the segment: loads mip 1 of texture 0 and checks the bytes.
  void stream_one_mip(Segment& seg) {
    SpscRingProducer<RequestRecord> requests = seg.request_producer();
    SpscRingConsumer<CompletionRecord> completions = seg.completion_consumer();
    RequestRecord r{};
    r.kind = static_cast<uint32_t>(RequestKind::kLoad);
    r.mip_level = 1;
    r.generation = 1;
    ASSERT_TRUE(requests.try_push(r));
    Doorbell(seg).ring();
    std::optional<CompletionRecord> c;
    const auto deadline = std::chrono::steady_clock::now() + kHangAfter;
    while (!(c = completions.try_pop()) && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(1ms);
    ASSERT_TRUE(c) << "no completion within " << kHangAfter.count() << " s";
    ASSERT_EQ(c->status, uint32_t(CompletionStatus::kOk));
    ASSERT_EQ(c->byte_size, 16u * 16u * 4u);
    const uint64_t offset = mip_chain_offset(TexelFormat::kRgba8, 32, 32, 1);
    EXPECT_EQ(std::memcmp(seg.slot(c->slot).data(), payload_.data() + offset, c->byte_size), 0);
    EXPECT_EQ(c->checksum, payload_checksum(payload_.data() + offset, c->byte_size));
  }

  bool wait_attached(Segment& seg, uint32_t want) {
    const auto deadline = std::chrono::steady_clock::now() + kHangAfter;
    while (seg.server_block().attached.v.load(std::memory_order_acquire) != want) {
      if (std::chrono::steady_clock::now() >= deadline) return false;
      std::this_thread::sleep_for(2ms);
    }
    return true;
  }

  // A forked child that creates the segment and sleeps until killed (optionally spawning the server itself,
  // as the renderer does). Returns the child's pid; `server_pid` gets the grandchild's when spawned.
  pid_t fork_owner(bool spawn_server_too, pid_t* server_pid) {
    int fds[2];
    if (pipe(fds) != 0) return -1;
    const pid_t pid = fork();
    if (pid == 0) {
      close(fds[0]);
      auto seg = Segment::create(name_, {});
      pid_t child_server = 0;
      if (seg.ok() && spawn_server_too) child_server = spawn_server(server_args(true));
      const int32_t msg = seg.ok() ? static_cast<int32_t>(child_server) : -1;
      (void)!write(fds[1], &msg, sizeof msg);
      for (;;) pause();  // killed by the test; never returns into gtest
    }
    close(fds[1]);
    int32_t msg = -1;
    const ssize_t n = read(fds[0], &msg, sizeof msg);
    close(fds[0]);
    if (n != sizeof msg || msg < 0) {
      kill(pid, SIGKILL);
      waitpid(pid, nullptr, 0);
      return -1;
    }
    if (server_pid) *server_pid = msg;
    g_children.push_back(pid);
    return pid;
  }

  std::string name_;
  fs::path dir_;
  std::vector<std::byte> payload_;
};

TEST_F(ServerProcessTest, BadArgumentsExitWithCode2) {
  const pid_t no_segment = spawn_server({"--scene", dir_.string()});
  EXPECT_EQ(wait_exit(no_segment, kHangAfter), 2);
  const pid_t bad_key = spawn_server({"--segment", name_, "--set", "server.no_such_key=1"});
  EXPECT_EQ(wait_exit(bad_key, kHangAfter), 2);
  const pid_t bad_range = spawn_server({"--segment", name_, "--set", "server.worker_threads=0"});
  EXPECT_EQ(wait_exit(bad_range, kHangAfter), 2);
}

TEST_F(ServerProcessTest, MissingSegmentExitsWithCode3WhenSpawned) {
  const pid_t pid = spawn_server(server_args(true));
  EXPECT_EQ(wait_exit(pid, kHangAfter), 3);
}

TEST_F(ServerProcessTest, AStandaloneServerStartedBeforeItsRendererWaitsForIt) {
  // Before, it exited with status 3 (no segment yet): a standalone server had to be started after the renderer.
  const pid_t pid = spawn_server(server_args(false));
  std::this_thread::sleep_for(300ms);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, WNOHANG), 0) << "the standalone server exited before any renderer came";
  const pid_t owner = fork_owner(false, nullptr);
  ASSERT_GT(owner, 0) << "owner child could not create the segment";
  auto seg = Segment::open(name_);
  ASSERT_TRUE(seg.ok()) << seg.error().message;
  ASSERT_TRUE(wait_attached(**seg, 1)) << "the waiting server never attached";
  stream_one_mip(**seg);
  kill(pid, SIGTERM);
  EXPECT_EQ(wait_exit(pid, kHangAfter), 0);
  kill(owner, SIGKILL);
  waitpid(owner, nullptr, 0);
}

TEST_F(ServerProcessTest, AStandaloneServerWithAWrongSceneExitsAtOnceNamingTheFile) {
  // Before, a standalone server started before its renderer waited silently with any --scene (a typo, an
  // unreadable texture table), and failed only when a renderer came, which then found no server.
  const fs::path log = dir_ / "stderr.txt";
  const fs::path missing = dir_ / "no-such-scene";
  const pid_t pid = spawn_server({"--segment", name_, "--scene", missing.string()}, log);
  EXPECT_EQ(wait_exit(pid, kHangAfter), 2);
  const std::string text = read_text(log);
  EXPECT_NE(text.find((missing / "textures.bin").string()), std::string::npos) << text;
  EXPECT_EQ(text.find("waiting for the next renderer"), std::string::npos) << text;
}

TEST_F(ServerProcessTest, AStandaloneServerWhoseGroundIsMissingExitsAtOnceNamingTheFile) {
  // scene.json names a page file (its "ground", issue 28) that is not there: said at start, not when the first
  // renderer comes.
  scene::Manifest m;
  m.name = "ground";
  m.texture_count = 1;
  m.texture_format = TexelFormat::kRgba8;
  m.ground = scene::GroundPages{"ground.tspages", {0, 0, 0}, 1.0};
  ASSERT_TRUE(scene::write_manifest(dir_, m).ok());
  const fs::path log = dir_ / "stderr.txt";
  const pid_t pid = spawn_server(server_args(), log);
  EXPECT_EQ(wait_exit(pid, kHangAfter), 2);
  const std::string text = read_text(log);
  EXPECT_NE(text.find((dir_ / "ground.tspages").string()), std::string::npos) << text;
}

TEST_F(ServerProcessTest, HeaderMismatchExitsWithCode3NamingTheField) {
  auto seg = Segment::create(name_, {});
  ASSERT_TRUE(seg.ok()) << seg.error().message;
  // As if the renderer were built from another layout version: the header sits just before the RendererBlock.
  auto* header =
      reinterpret_cast<SegmentHeader*>(reinterpret_cast<std::byte*>(&(*seg)->renderer_block()) - kSegmentHeaderBytes);
  header->layout_version = kLayoutVersion + 1;
  const fs::path log = dir_ / "stderr.txt";
  const pid_t pid = spawn_server(server_args(), log);
  EXPECT_EQ(wait_exit(pid, kHangAfter), 3);
  std::ifstream f(log);
  std::ostringstream buffer;
  buffer << f.rdbuf();
  const std::string text = buffer.str();
  EXPECT_NE(text.find("layout_version"), std::string::npos) << text;
}

TEST_F(ServerProcessTest, MissingSceneExitsWithCode2) {
  auto seg = Segment::create(name_, {});
  ASSERT_TRUE(seg.ok()) << seg.error().message;
  const pid_t pid = spawn_server({"--segment", name_, "--scene", (dir_ / "nope").string()});
  EXPECT_EQ(wait_exit(pid, kHangAfter), 2);
}

TEST_F(ServerProcessTest, AServerReadingAnotherSceneRefusesTheSegmentNamingBoth) {
  // The renderer states its texture table in the header. A server whose scene differs used to serve anyway:
  // every answer about textures the renderer does not have was refused one by one as a protocol error (994
  // in a 400-frame run). Now it refuses before attaching, naming both tables: a spawned server exits 2, a
  // standalone one marks the segment refused (ServerBlock::refused_by, for the renderer to name it) and
  // waits for the next renderer, which it serves.
  SegmentParams other;
  other.texture_count = 999;
  other.texture_table_fingerprint = 0x1234;
  auto seg = Segment::create(name_, other);
  ASSERT_TRUE(seg.ok()) << seg.error().message;
  const fs::path spawned_log = dir_ / "spawned.txt";
  const pid_t spawned = spawn_server(server_args(/*spawned=*/true), spawned_log);
  EXPECT_EQ(wait_exit(spawned, kHangAfter), 2);
  std::string text = read_text(spawned_log);
  EXPECT_NE(text.find("texture table of 999 textures"), std::string::npos) << text;
  EXPECT_NE(text.find("has 1 (fingerprint"), std::string::npos) << text;
  EXPECT_NE(text.find("read different scenes"), std::string::npos) << text;
  EXPECT_EQ((*seg)->server_block().pid.v.load(), 0u) << "it claimed the segment";
  EXPECT_EQ((*seg)->server_block().refused_by.v.load(), 0u) << "a spawned server's refusal is its exit status";

  const fs::path log = dir_ / "standalone.txt";
  const pid_t pid = spawn_server(server_args(), log);
  const auto deadline = std::chrono::steady_clock::now() + kHangAfter;
  while ((*seg)->server_block().refused_by.v.load() == 0 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(2ms);
  }
  EXPECT_EQ((*seg)->server_block().refused_by.v.load(), static_cast<uint32_t>(pid));
  EXPECT_EQ((*seg)->server_block().pid.v.load(), 0u) << "it claimed the segment";
  std::this_thread::sleep_for(300ms);
  int status = 0;
  EXPECT_EQ(waitpid(pid, &status, WNOHANG), 0) << "a standalone server must wait for the next renderer";
  // The refusal is published before it is logged: wait for the line rather than for a fixed time.
  const auto logged_by = std::chrono::steady_clock::now() + kHangAfter;
  while ((text = read_text(log)).find("refused, waiting for the next renderer") == std::string::npos &&
         std::chrono::steady_clock::now() < logged_by) {
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_NE(text.find("read different scenes"), std::string::npos) << text;
  EXPECT_NE(text.find("refused, waiting for the next renderer"), std::string::npos) << text;
  seg.value().reset();  // the creator's mapping goes, and with it the name
  // The next renderer on the name reads the same table (this test's one texture): the same server serves it.
  SegmentParams same;
  same.texture_count = 1;
  same.texture_table_fingerprint =
      texture_table_step(kTextureTableSeed, 32, 32, full_mip_count(32, 32), uint32_t(TexelFormat::kRgba8));
  auto seg2 = Segment::create(name_, same);
  ASSERT_TRUE(seg2.ok()) << seg2.error().message;
  ASSERT_TRUE(wait_attached(**seg2, 1)) << "the waiting server never attached to the next renderer's segment:\n"
                                        << read_text(log);
  EXPECT_EQ((*seg2)->server_block().pid.v.load(), static_cast<uint32_t>(pid));
  stream_one_mip(**seg2);
  kill(pid, SIGTERM);
  EXPECT_EQ(wait_exit(pid, kHangAfter), 0);
}

TEST_F(ServerProcessTest, StreamsAMipAndExitsCleanlyOnSigterm) {
  auto seg = Segment::create(name_, {});
  ASSERT_TRUE(seg.ok()) << seg.error().message;
  const pid_t pid = spawn_server(server_args());
  ASSERT_TRUE(wait_attached(**seg, 1)) << "server never attached";
  EXPECT_EQ((*seg)->server_block().pid.v.load(), static_cast<uint32_t>(pid));
  EXPECT_TRUE(process_alive(pid, (*seg)->server_block().start_time.v.load()));
  stream_one_mip(**seg);
  kill(pid, SIGTERM);
  EXPECT_EQ(wait_exit(pid, kHangAfter), 0);
  EXPECT_EQ((*seg)->server_block().attached.v.load(), 0u);
}

TEST_F(ServerProcessTest, SpawnedServerExitsWhenTheSegmentOwnerDies) {
  const pid_t owner = fork_owner(false, nullptr);
  ASSERT_GT(owner, 0) << "owner child could not create the segment";
  auto seg = Segment::open(name_);
  ASSERT_TRUE(seg.ok()) << seg.error().message;
  const pid_t pid = spawn_server(server_args(true));
  ASSERT_TRUE(wait_attached(**seg, 1));
  stream_one_mip(**seg);
  kill(owner, SIGKILL);
  waitpid(owner, nullptr, 0);
  EXPECT_EQ(wait_exit(pid, kHangAfter), 0) << "the server must notice its renderer's death (pidfd) and exit 0";
}

TEST_F(ServerProcessTest, StandaloneServerWaitsForTheNextRendererOnTheSameName) {
  const pid_t first = fork_owner(false, nullptr);
  ASSERT_GT(first, 0) << "owner child could not create the segment";
  auto seg = Segment::open(name_);
  ASSERT_TRUE(seg.ok()) << seg.error().message;
  const pid_t pid = spawn_server(server_args(false));
  ASSERT_TRUE(wait_attached(**seg, 1));
  stream_one_mip(**seg);
  const uint64_t first_epoch = (*seg)->header().epoch;
  kill(first, SIGKILL);
  waitpid(first, nullptr, 0);
  ASSERT_TRUE(wait_attached(**seg, 0)) << "the server must detach from the dead renderer's segment";
  seg.value().reset();
  // The dead renderer's name is still there (stale): the server must not attach to it again.
  std::this_thread::sleep_for(300ms);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, WNOHANG), 0) << "a standalone server must outlive its renderer";
  // The next renderer removes the stale segment and creates its own under the same name. Any renderer that
  // starts meanwhile (another test's, in parallel) sweeps every stale "texstream-" segment, so it may be gone
  // already: either way it must be gone now.
  EXPECT_LE(Segment::remove_stale(name_), 1);
  ASSERT_FALSE(fs::exists("/dev/shm/" + name_)) << "the stale segment is still there";
  const pid_t second = fork_owner(false, nullptr);
  ASSERT_GT(second, 0);
  auto seg2 = Segment::open(name_);
  ASSERT_TRUE(seg2.ok()) << seg2.error().message;
  EXPECT_NE((*seg2)->header().epoch, first_epoch);
  ASSERT_TRUE(wait_attached(**seg2, 1)) << "the standalone server never attached to the new segment";
  stream_one_mip(**seg2);
  kill(pid, SIGTERM);
  EXPECT_EQ(wait_exit(pid, kHangAfter), 0);
  kill(second, SIGKILL);
  waitpid(second, nullptr, 0);
}

TEST_F(ServerProcessTest, ASecondServerOnASegmentTouchesNothing) {
  // The rings have one consumer and one producer: a second server (a standalone one and the renderer's own
  // child on one protocol.segment_name) must not attach alongside the first. Before, both did, and the
  // renderer saw slots released twice and protocol errors.
  auto seg = Segment::create(name_, {});
  ASSERT_TRUE(seg.ok()) << seg.error().message;
  const pid_t first = spawn_server(server_args(false));
  ASSERT_TRUE(wait_attached(**seg, 1));
  stream_one_mip(**seg);
  // A spawned one leaves at once, naming the holder.
  const fs::path log = dir_ / "second.txt";
  const pid_t second = spawn_server(server_args(true), log);
  EXPECT_EQ(wait_exit(second, kHangAfter), 3);
  std::ifstream f(log);
  std::ostringstream text;
  text << f.rdbuf();
  EXPECT_NE(text.str().find("already served by texstream-server pid " + std::to_string(first)), std::string::npos)
      << text.str();
  // A standalone one waits (it does not exit, and does not take the segment).
  const pid_t third = spawn_server(server_args(false));
  std::this_thread::sleep_for(300ms);
  int status = 0;
  EXPECT_EQ(waitpid(third, &status, WNOHANG), 0) << "a standalone server must wait for the segment to be free";
  EXPECT_EQ((*seg)->server_block().pid.v.load(), static_cast<uint32_t>(first));
  stream_one_mip(**seg);
  stream_one_mip(**seg);
  // The first goes; once the renderer has reset the block (as it does when it sees a server's death), the
  // waiting one takes over and serves.
  kill(first, SIGKILL);
  waitpid(first, nullptr, 0);
  (*seg)->reset_after_server_death();
  ASSERT_TRUE(wait_attached(**seg, 1)) << "the waiting standalone server never took the free segment";
  EXPECT_EQ((*seg)->server_block().pid.v.load(), static_cast<uint32_t>(third));
  stream_one_mip(**seg);
  kill(third, SIGTERM);
  EXPECT_EQ(wait_exit(third, kHangAfter), 0);
}

TEST_F(ServerProcessTest, Sigusr1PrintsStatisticsAndKeepsServing) {
  auto seg = Segment::create(name_, {});
  ASSERT_TRUE(seg.ok()) << seg.error().message;
  const fs::path log = dir_ / "server.log";
  const pid_t pid = spawn_server(server_args(), log);
  ASSERT_TRUE(wait_attached(**seg, 1));
  stream_one_mip(**seg);
  kill(pid, SIGUSR1);
  std::string text;
  const auto deadline = std::chrono::steady_clock::now() + kHangAfter;
  while (text.find("latency miss") == std::string::npos && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(10ms);
    text = read_text(log);
  }
  EXPECT_NE(text.find("statistics (SIGUSR1)"), std::string::npos) << text;
  EXPECT_NE(text.find("1 loads ok"), std::string::npos) << text;
  EXPECT_NE(text.find("read amplification"), std::string::npos) << text;
  int status = 0;
  EXPECT_EQ(waitpid(pid, &status, WNOHANG), 0) << "SIGUSR1 must not stop the server";
  kill(pid, SIGTERM);
  EXPECT_EQ(wait_exit(pid, kHangAfter), 0);
}

TEST_F(ServerProcessTest, SpawnedServerDiesWithItsParent) {
  pid_t server = 0;
  const pid_t owner = fork_owner(true, &server);
  ASSERT_GT(owner, 0);
  ASSERT_GT(server, 0);
  auto seg = Segment::open(name_);
  ASSERT_TRUE(seg.ok()) << seg.error().message;
  ASSERT_TRUE(wait_attached(**seg, 1));
  const uint64_t start = (*seg)->server_block().start_time.v.load();
  ASSERT_TRUE(process_alive(server, start));
  kill(owner, SIGKILL);
  waitpid(owner, nullptr, 0);
  // The server is the owner's child, not ours: watch its identity (pid + start time) disappear.
  const auto deadline = std::chrono::steady_clock::now() + kHangAfter;
  while (process_alive(server, start) && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(5ms);
  EXPECT_FALSE(process_alive(server, start)) << "a --spawned server must die with its parent";
}

}  // namespace
}  // namespace texstream
