// Issue 4 end to end: the texture server reading a generated scene through a real nginx on loopback (the
// project's config/nginx/texstream-origin.conf.in), its disk cache across a restart with the origin gone, a
// second server refused on the same cache folder, bimodal scheduling over slow storage, and every origin
// failure of item 5 — origin down, 404, 500, truncated body, wrong Content-Range, slowloris stall — each
// answered with an error completion before its deadline, logged with the URL, the server still serving.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>
#include <sys/wait.h>

#include <chrono>
#include <filesystem>
#include <mutex>
#include <sstream>
#include <thread>

#include "../support/patience.hpp"
#include "fake_http_origin.hpp"
#include "nginx_origin.hpp"
#include "process_test_support.hpp"
#include "server_harness.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/server/load/mip_loader.hpp"
#include "texstream/server/storage/posix_storage.hpp"
#include "texstream/server/storage/storage_stack.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using texstream::test::kHangAfter;
using texstream::test::promptly;

namespace texstream::test {
namespace {

constexpr uint32_t kTextures = 8;

class StorageOriginTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = fresh_dir("texstream_storage_", "origin");
    scene_ = root_ / "scene";
    const std::string gen = std::string(TEXSTREAM_BIN_DIR) + "/texstream-gen --out " + scene_.string() +
                            " --textures " + std::to_string(kTextures) + " --seed 11 --format rgba8 --threads 1";
    ASSERT_EQ(run_logged(gen, root_ / "gen.log"), 0) << slurp(root_ / "gen.log");
    std::string error;
    nginx_ = NginxOrigin::start(scene_, fs::path(TEXSTREAM_SOURCE_DIR) / "config/nginx/texstream-origin.conf.in",
                                root_ / "nginx", error)
                 .release();
    ASSERT_NE(nginx_, nullptr) << error;
  }
  static void TearDownTestSuite() {
    delete nginx_;  // stops nginx
    nginx_ = nullptr;
    fs::remove_all(root_);
  }

  void SetUp() override {
    // A failed suite set-up (no nginx, no scene) fails every test rather than skipping it.
    if (!nginx_) FAIL() << "suite setup failed: nginx did not start (see the first failure)";
    // Capture the server's log to check that failures name their URL.
    log_ = std::make_shared<std::ostringstream>();
    auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(*log_);
    previous_ = spdlog::default_logger();
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("storage-test", sink));
  }
  void TearDown() override {
    if (previous_) spdlog::set_default_logger(previous_);
  }

  std::string log_text() {
    spdlog::default_logger()->flush();
    return log_->str();
  }

  static std::vector<WantedMip> every_mip() {
    std::vector<WantedMip> w;
    auto table = scene::read_texture_table(scene_);
    EXPECT_TRUE(table.ok());
    if (!table.ok()) return w;
    for (uint32_t t = 0; t < table->size(); ++t) {
      for (uint32_t m = (*table)[t].mip_count; m-- > 0;) w.push_back({t, m, float(m)});  // coarsest first
    }
    return w;
  }

  // The answers a local origin gives: what every other origin must reproduce byte for byte.
  static DriveResult local_reference(const std::vector<WantedMip>& wanted) {
    server::PosixStorage storage;
    std::string error;
    auto h = ServerHarness::start(scene_, ServerConfig{}, storage, error);
    EXPECT_NE(h, nullptr) << error;
    if (!h) return {};
    return drive(*h, wanted, kHangAfter);
  }

  static StorageConfig http_config(const std::string& origin) {
    StorageConfig c;
    c.origin = origin;
    c.connect_timeout_ms = 500;
    c.request_timeout_ms = 2000;
    c.low_speed_bytes_s = 1024;
    c.low_speed_time_s = 1;
    c.retries = 1;
    c.retry_backoff_ms = 20;
    return c;
  }

  // One load through `origin`: it must end in `expected` within `deadline` (what the configured timeouts
  // allow) plus the time its work takes on a busy machine, the log must name `url_part`, and the server must
  // still answer the next request (the renderer keeps drawing).
  void expect_failure(const StorageConfig& config, CompletionStatus expected, std::chrono::milliseconds deadline,
                      const std::string& url_part) {
    auto stack = server::make_storage_stack(config, scene_);
    ASSERT_TRUE(stack.ok()) << stack.error().message;
    std::string error;
    auto h = ServerHarness::start((*stack)->scene_dir, ServerConfig{}, (*stack)->storage(), error);
    ASSERT_NE(h, nullptr) << error;
    const auto t0 = std::chrono::steady_clock::now();
    DriveResult r = drive(*h, {{0, 0, 1.0f}}, kHangAfter);
    const auto took = std::chrono::steady_clock::now() - t0;
    ASSERT_TRUE(r.complete) << "no final answer within " << kHangAfter.count() << " s";
    EXPECT_EQ(r.status[0], static_cast<uint32_t>(expected))
        << "got " << to_string(static_cast<CompletionStatus>(r.status[0]));
    EXPECT_LT(took, deadline + promptly(100ms))
        << "the error came after " << std::chrono::duration_cast<std::chrono::milliseconds>(took).count() << " ms";
    EXPECT_NE(log_text().find(url_part), std::string::npos) << "the log does not name " << url_part << ":\n"
                                                            << log_text();
    // Still serving: another texture's request is answered too (by the same failing origin: an error).
    DriveResult again = drive(*h, {{1, 0, 1.0f}}, kHangAfter);
    EXPECT_TRUE(again.complete);
  }

  static inline fs::path root_;
  static inline fs::path scene_;
  static inline NginxOrigin* nginx_ = nullptr;
  std::shared_ptr<std::ostringstream> log_;
  std::shared_ptr<spdlog::logger> previous_;
};

TEST_F(StorageOriginTest, NginxOriginServesEveryMipAndTheDiskCacheSurvivesARestartWithTheOriginDown) {
  const std::vector<WantedMip> wanted = every_mip();
  ASSERT_FALSE(wanted.empty());
  const DriveResult reference = local_reference(wanted);
  ASSERT_TRUE(reference.complete);
  ASSERT_EQ(reference.ok, wanted.size());

  const fs::path cache = root_ / "cache_restart";
  StorageConfig c = http_config(nginx_->url("unlimited"));
  c.disk_cache_dir = cache.string();
  uint64_t from_origin = 0;
  {
    auto stack = server::make_storage_stack(c, scene_);
    ASSERT_TRUE(stack.ok()) << stack.error().message;
    std::string error;
    auto h = ServerHarness::start((*stack)->scene_dir, ServerConfig{}, (*stack)->storage(), error);
    ASSERT_NE(h, nullptr) << error;
    const DriveResult r = drive(*h, wanted, kHangAfter);
    ASSERT_TRUE(r.complete);
    EXPECT_EQ(r.ok, wanted.size());
    EXPECT_EQ(r.checksum, reference.checksum) << "bytes through nginx differ from the local files";
    from_origin = (*stack)->caching->counters().bytes_from_origin.load();
    EXPECT_GT(from_origin, 0u);
    EXPECT_GT((*stack)->http->counters().requests.load(), 0u);
  }
  // Restart: a new server on the same cache folder, its origin now a port nobody listens on.
  c.origin = "http://127.0.0.1:" + std::to_string(free_loopback_port());
  auto stack = server::make_storage_stack(c, scene_);
  ASSERT_TRUE(stack.ok()) << stack.error().message;
  std::string error;
  auto h = ServerHarness::start((*stack)->scene_dir, ServerConfig{}, (*stack)->storage(), error);
  ASSERT_NE(h, nullptr) << error;
  const DriveResult r = drive(*h, wanted, kHangAfter);
  ASSERT_TRUE(r.complete);
  EXPECT_EQ(r.ok, wanted.size());
  EXPECT_EQ(r.checksum, reference.checksum);
  EXPECT_EQ((*stack)->caching->counters().bytes_from_origin.load(), 0u);
  // Every byte came from the disk cache; at most what was fetched (two remote workers may both have fetched
  // a texture's header the first time).
  EXPECT_GT((*stack)->caching->counters().bytes_from_disk_cache.load(), 0u);
  EXPECT_LE((*stack)->caching->counters().bytes_from_disk_cache.load(), from_origin);
}

TEST_F(StorageOriginTest, ASecondServerOnTheSameCacheFolderIsRefusedClearly) {
  StorageConfig c = http_config(nginx_->url("unlimited"));
  c.disk_cache_dir = (root_ / "cache_shared").string();
  auto first = server::make_storage_stack(c, scene_);
  ASSERT_TRUE(first.ok()) << first.error().message;
  auto second = server::make_storage_stack(c, scene_);
  ASSERT_FALSE(second.ok());
  EXPECT_NE(second.error().message.find("in use by another texstream-server"), std::string::npos)
      << second.error().message;
  EXPECT_NE(second.error().message.find(c.disk_cache_dir), std::string::npos);
  first.value().reset();
  auto third = server::make_storage_stack(c, scene_);  // the lock goes with its owner
  EXPECT_TRUE(third.ok());
}

TEST_F(StorageOriginTest, RamHitsAreServedWhileASlowFetchIsInFlightAndWaitingFetchesGoStale) {
  StorageConfig c;
  c.slow_enabled = true;
  c.slow_latency_ms = 1500;  // long next to any scheduling delay under ASan on a loaded 2-core machine
  auto stack = server::make_storage_stack(c, scene_);
  ASSERT_TRUE(stack.ok());
  ServerConfig sc;
  sc.remote_fetches_in_flight = 1;
  std::string error;
  auto h = ServerHarness::start((*stack)->scene_dir, sc, (*stack)->storage(), error);
  ASSERT_NE(h, nullptr) << error;
  auto table = scene::read_texture_table(scene_);
  ASSERT_TRUE(table.ok());
  const uint32_t coarsest = (*table)[2].mip_count - 1;
  // Warm the RAM cache with texture 2's coarsest mip (header + mip: two slow reads).
  ASSERT_TRUE(drive(*h, {{2, coarsest, 1.0f}}, kHangAfter).complete);
  // Texture 0 mip 0 takes the only remote-fetch worker; texture 1 waits for it; texture 2 is a RAM hit.
  const uint64_t fetches_before = h->server().remote_fetches();
  ASSERT_TRUE(h->push(0, 0, 100, 5.0f));
  h->ring();
  // Wait until the remote-fetch worker has taken texture 0 (its fetch then runs >= 1500 ms). A fixed sleep
  // (50 ms, then 250 ms) was too short under ASan on a loaded 2-core machine: texture 1 was taken instead and
  // could no longer go stale.
  const auto taken_deadline = std::chrono::steady_clock::now() + kHangAfter;
  while (h->server().remote_fetches() == fetches_before && std::chrono::steady_clock::now() < taken_deadline) {
    std::this_thread::sleep_for(1ms);
  }
  ASSERT_GT(h->server().remote_fetches(), fetches_before) << "texture 0 never reached a remote-fetch worker";
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_TRUE(h->push(1, 0, 100, 4.0f));
  ASSERT_TRUE(h->push(2, coarsest, 100, 3.0f));
  h->ring();
  auto ms_since = [](auto t) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
  };
  double hit_ms = -1, cancelled_ms = -1;
  bool texture0_done = false, next_batch_sent = false;
  bool hit_before_texture0 = false, cancelled_before_texture0 = false;
  std::chrono::steady_clock::time_point t1;
  const double give_up_ms = std::chrono::duration<double, std::milli>(kHangAfter).count();
  while (ms_since(t0) < give_up_ms && (hit_ms < 0 || cancelled_ms < 0)) {
    // Completions come in ring order: what came before texture 0's did not wait behind its fetch.
    h->poll([&](const CompletionRecord& rec, std::span<const std::byte>) {
      if (rec.texture_id == 2 && rec.status == uint32_t(CompletionStatus::kOk) && hit_ms < 0) {
        hit_ms = ms_since(t0);
        hit_before_texture0 = !texture0_done;
      }
      if (rec.texture_id == 1 && rec.status == uint32_t(CompletionStatus::kCancelled)) {
        cancelled_ms = ms_since(t1);
        cancelled_before_texture0 = !texture0_done;
      }
      if (rec.texture_id == 0) texture0_done = true;
    });
    if (hit_ms >= 0 && !next_batch_sent) {
      // The renderer's next cycle does not ask for texture 1 again: its waiting fetch is stale.
      next_batch_sent = true;
      t1 = std::chrono::steady_clock::now();
      ASSERT_TRUE(h->push(2, coarsest, 101, 1.0f));
      h->ring();
    }
    std::this_thread::sleep_for(100us);
  }
  // The hit and the cancellation came before the >= 1500 ms fetch ended: neither waited behind it. Told by
  // their order, not by a time (200 ms, then 750 ms, failed under ASan on a loaded 2-core machine).
  std::printf("hit after %.1f ms, stale load cancelled %.1f ms after the next batch\n", hit_ms, cancelled_ms);
  ASSERT_GE(hit_ms, 0.0);
  EXPECT_TRUE(hit_before_texture0) << "texture 0's slow fetch ended before the hit: the hit waited for it";
  ASSERT_GE(cancelled_ms, 0.0) << "the waiting remote load was not cancelled by the newer batch";
  EXPECT_TRUE(cancelled_before_texture0) << "the stale load was cancelled only after the fetch it waited for";
}

TEST_F(StorageOriginTest, TheServerProcessReadsThroughNginxAndASecondOneOnItsCacheFolderIsRefused) {
  std::string error;
  auto h = ServerHarness::create_segment_only(error);
  ASSERT_NE(h, nullptr) << error;
  const std::string exe = std::string(TEXSTREAM_BIN_DIR) + "/texstream-server";
  const fs::path cache = root_ / "cache_process";
  const std::vector<std::string> args{exe,
                                      "--segment",
                                      h->segment_name(),
                                      "--scene",
                                      scene_.string(),
                                      "--set",
                                      "storage.origin=" + nginx_->url("unlimited"),
                                      "--set",
                                      "storage.disk_cache_dir=" + cache.string()};
  const std::string log = (root_ / "server_process.log").string();
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) ::dup2(fd, 2);
    ::execv(exe.c_str(), argv.data());
    ::_exit(127);
  }
  ASSERT_GT(pid, 0);
  struct Reaper {  // stops the server whatever happens below
    pid_t pid;
    ~Reaper() {
      if (pid <= 0) return;  // never kill(0, ...): that is the whole process group
      ::kill(pid, SIGKILL);
      ::waitpid(pid, nullptr, 0);
    }
  } reaper{pid};
  const auto deadline = std::chrono::steady_clock::now() + kHangAfter;
  while (h->server_block().attached.v.load() != 1 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(5ms);
  }
  ASSERT_EQ(h->server_block().attached.v.load(), 1u) << slurp(log);

  // A second server on the same cache folder exits 2 (configuration) naming the folder.
  std::string cmd;
  for (const std::string& a : args) cmd += "'" + a + "' ";
  EXPECT_EQ(run_logged(cmd, root_ / "second_server.log"), 2);
  const std::string second = slurp(root_ / "second_server.log");
  EXPECT_NE(second.find("in use by another texstream-server"), std::string::npos) << second;
  EXPECT_NE(second.find(cache.string()), std::string::npos) << second;

  // The first one serves through nginx.
  const DriveResult r = drive(*h, {{0, 0, 1.0f}, {1, 0, 1.0f}}, kHangAfter);
  EXPECT_TRUE(r.complete);
  EXPECT_EQ(r.ok, 2u) << slurp(log);
  ::kill(pid, SIGTERM);
  int status = 0;
  bool reaped = false;
  const auto stop_deadline = std::chrono::steady_clock::now() + kHangAfter;
  while (!(reaped = ::waitpid(pid, &status, WNOHANG) == pid) && std::chrono::steady_clock::now() < stop_deadline) {
    std::this_thread::sleep_for(5ms);
  }
  if (reaped) reaper.pid = 0;  // else the reaper kills it
  ASSERT_TRUE(reaped) << "texstream-server did not stop within 5 s of SIGTERM";
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << slurp(log);
  EXPECT_NE(slurp(log).find("disk cache"), std::string::npos);
}

// An origin that does not answer (nothing listens: connection refused) is kTimedOut, which the renderer asks
// again for without counting it against the texture. It was kIoError: 4 of them and the renderer marked the
// texture broken for the run, so an origin down for 2.5 s (an nginx restart) left textures unstreamed for good.
TEST_F(StorageOriginTest, OriginDownIsTimedOutWithinTheConnectTimeout) {
  const std::string url = "http://127.0.0.1:" + std::to_string(free_loopback_port());
  expect_failure(http_config(url), CompletionStatus::kTimedOut, 3000ms, url);
}

TEST_F(StorageOriginTest, ServiceUnavailableIsTimedOut) {
  expect_failure(http_config(nginx_->url("fail503")), CompletionStatus::kTimedOut, 2000ms, "HTTP 503");
}

// The same server, its origin down and then back (nginx stopped and started again on its port): while down,
// every ask is answered kTimedOut, as many times as asked; once back, the same mips are served, byte-equal to
// the local files, and the down time's warnings are rate-limited.
TEST_F(StorageOriginTest, AnOriginThatComesBackIsReadAgain) {
  std::string error;
  auto origin = NginxOrigin::start(scene_, fs::path(TEXSTREAM_SOURCE_DIR) / "config/nginx/texstream-origin.conf.in",
                                   root_ / "nginx_comeback", error);
  ASSERT_NE(origin, nullptr) << error;
  const std::vector<WantedMip> wanted{{0, 0, 1.0f}, {1, 1, 1.0f}, {2, 0, 1.0f}};
  const DriveResult reference = local_reference(wanted);
  ASSERT_EQ(reference.ok, wanted.size());
  StorageConfig c = http_config(origin->url("unlimited"));
  c.retries = 0;
  auto stack = server::make_storage_stack(c, scene_);
  ASSERT_TRUE(stack.ok()) << stack.error().message;
  auto h = ServerHarness::start((*stack)->scene_dir, ServerConfig{}, (*stack)->storage(), error);
  ASSERT_NE(h, nullptr) << error;
  origin->stop();
  const auto outage_start = std::chrono::steady_clock::now();
  for (int round = 0; round < 6; ++round) {
    const DriveResult down = drive(*h, wanted, kHangAfter);
    ASSERT_TRUE(down.complete) << "round " << round;
    for (size_t i = 0; i < wanted.size(); ++i) {
      EXPECT_EQ(down.status[i], static_cast<uint32_t>(CompletionStatus::kTimedOut))
          << "round " << round << ", mip " << i << ": " << to_string(static_cast<CompletionStatus>(down.status[i]));
    }
  }
  const size_t warnings = [&] {
    size_t n = 0;
    const std::string text = log_text();
    for (size_t at = text.find("timed out ("); at != std::string::npos; at = text.find("timed out (", at + 1)) ++n;
    return n;
  }();
  // One warning per kTimedOutLogPeriod (5 s): 18 failed loads log 1 or 2 on a quiet machine, more only if
  // the outage itself lasted longer.
  const auto outage = std::chrono::steady_clock::now() - outage_start;
  const auto periods = static_cast<size_t>(outage / server::MipLoader::kTimedOutLogPeriod);
  EXPECT_LE(warnings, periods + 2) << "18 failed loads should log one warning per 5 s:\n" << log_text();
  ASSERT_TRUE(origin->restart()) << "nginx did not come back on port " << origin->port();
  const DriveResult back = drive(*h, wanted, kHangAfter);
  ASSERT_TRUE(back.complete);
  EXPECT_EQ(back.ok, wanted.size());
  EXPECT_EQ(back.checksum, reference.checksum);
  // The warnings left out during the outage are counted in one line once the rate limit's period has passed,
  // although no load times out any more (the count used to wait for the next timeout, so was never printed).
  const auto deadline = std::chrono::steady_clock::now() + server::MipLoader::kTimedOutLogPeriod + kHangAfter;
  while (log_text().find("more load(s) timed out") == std::string::npos &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(20ms);
  }
  const std::string text = log_text();
  const size_t at = text.find("more load(s) timed out");
  ASSERT_NE(at, std::string::npos) << "the outage's left-out warnings were never counted:\n" << text;
  const size_t left_out = std::stoul(text.substr(text.rfind(' ', at - 2) + 1));
  EXPECT_EQ(left_out + warnings, 6 * wanted.size()) << text;
}

TEST_F(StorageOriginTest, NotFoundIsNotFound) {
  expect_failure(http_config(nginx_->url("missing")), CompletionStatus::kNotFound, 2000ms, nginx_->url("missing"));
}

TEST_F(StorageOriginTest, ServerErrorIsRetriedThenAnIoError) {
  expect_failure(http_config(nginx_->url("fail500")), CompletionStatus::kIoError, 2000ms, "HTTP 500");
}

TEST_F(StorageOriginTest, TruncatedBodyIsAnIoError) {
  FakeHttpOrigin fake(FakeHttpOrigin::Mode::kTruncatedBody, scene_);
  expect_failure(http_config(fake.url()), CompletionStatus::kIoError, 3000ms, fake.url());
  EXPECT_GE(fake.requests(), 2u) << "a truncated body is retried";
}

TEST_F(StorageOriginTest, WrongContentRangeIsAnIoErrorAndNeverServed) {
  FakeHttpOrigin fake(FakeHttpOrigin::Mode::kWrongContentRange, scene_);
  expect_failure(http_config(fake.url()), CompletionStatus::kIoError, 3000ms, "Content-Range");
}

TEST_F(StorageOriginTest, SlowlorisStallTimesOutWithinTheLowSpeedLimit) {
  FakeHttpOrigin fake(FakeHttpOrigin::Mode::kSlowloris, scene_);
  StorageConfig c = http_config(fake.url());
  c.retries = 0;
  // low_speed_time_s = 1: a trickle of 2 bytes/s is cut after about 1-2 s (curl checks once a second).
  expect_failure(c, CompletionStatus::kTimedOut, 3500ms, fake.url());
}

}  // namespace
}  // namespace texstream::test
