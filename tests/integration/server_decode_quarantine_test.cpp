// Issue 9: a file that crashed (or hung) the decode helper twice is quarantined for the server's life: every
// later decode of it is refused at once with an error naming it, no helper is started for it, other files
// keep decoding, and a file the helper merely rejects (an ordinary corrupt file) is never quarantined.
// The crashes are real: texstream-decode's test hooks (TEXSTREAM_DECODE_CRASH_ON / _HANG_ON, decode/main.cpp)
// make the real helper abort() or hang on paths containing a marker.
#include <unistd.h>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "../support/patience.hpp"
#include "scoped_env.hpp"
#include "server_harness.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/common/texel_format.hpp"
#include "texstream/server/decode/decode_helper_pool.hpp"
#include "texstream/server/dispatch/worker_pool.hpp"
#include "texstream/server/load/texture_file_index.hpp"
#include "texstream/server/storage/posix_storage.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace texstream::server {
namespace {

const fs::path kHelper = fs::path(TEXSTREAM_BIN_DIR) / "texstream-decode";

// 64x32 RGB tiled mipmapped TIFF, as maketx writes it (7 levels).
void make_tx(const fs::path& out) {
  OIIO::ImageSpec spec(64, 32, 3, OIIO::TypeDesc::UINT8);
  OIIO::ImageBuf src(spec);
  for (int y = 0; y < 32; ++y) {
    for (int x = 0; x < 64; ++x) {
      float px[3] = {float(x) / 64.0f, float(y) / 32.0f, float((x * 7 + y * 3) % 16) / 15.0f};
      src.setpixel(x, y, px, 3);
    }
  }
  OIIO::ImageSpec config;
  config.tile_width = 16;
  config.tile_height = 16;
  fs::create_directories(out.parent_path());
  ASSERT_TRUE(OIIO::ImageBufAlgo::make_texture(OIIO::ImageBufAlgo::MakeTxTexture, src, out.string(), config))
      << OIIO::geterror();
}

void write_garbage(const fs::path& out) {
  fs::create_directories(out.parent_path());
  std::ofstream f(out, std::ios::binary);
  for (int i = 0; i < 5000; ++i) f.put(static_cast<char>((i * 7919) >> 3));
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

using test::ScopedEnv;

class DecodeQuarantineTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("texstream-quarantine-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    make_tx(dir_ / "good.tx");
    fs::copy_file(dir_ / "good.tx", dir_ / "hostile-marker.tx");  // intact: only the hook makes it crash
    write_garbage(dir_ / "garbage.tx");
  }
  void TearDown() override { fs::remove_all(dir_); }

  Status decode(DecodeHelperPool& pool, const std::string& name, uint32_t level = 0) {
    const fs::path p = dir_ / name;
    Result<std::unique_ptr<StorageFile>> f = storage_.open(p);
    EXPECT_TRUE(f.ok());
    if (!f.ok()) return f.error();
    const Extent2D e = mip_extent(64, 32, level);
    std::vector<std::byte> out(size_t{e.width} * e.height * 4);
    uint64_t bytes_read = 0;
    return pool.decode(**f, p, level, e, out, bytes_read);
  }

  fs::path dir_;
  PosixStorage storage_;
};

TEST_F(DecodeQuarantineTest, AFileThatCrashedTheHelperTwiceIsRefusedAtOnceWithoutAHelper) {
  ScopedEnv hook("TEXSTREAM_DECODE_CRASH_ON", "hostile-marker");
  DecodeHelperPool pool(kHelper);
  const std::string bad = (dir_ / "hostile-marker.tx").string();

  ASSERT_TRUE(decode(pool, "good.tx").ok());
  EXPECT_EQ(pool.helpers_started(), 1u);
  for (int crash = 1; crash <= 2; ++crash) {
    const Status s = decode(pool, "hostile-marker.tx", static_cast<uint32_t>(crash - 1));
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().code, ErrorCode::kCorrupt);
    EXPECT_TRUE(contains(s.error().message, bad)) << s.error().message;
    EXPECT_TRUE(contains(s.error().message, "signal 6")) << s.error().message;  // SIGABRT: abort()
    EXPECT_FALSE(contains(s.error().message, "quarantined")) << s.error().message;
    // A good file between the crashes: the crashed helper is replaced, the file decodes.
    const Status good = decode(pool, "good.tx", 1);
    ASSERT_TRUE(good.ok()) << good.error().message;
  }
  // good, crash #1, (new) good, crash #2, (new) good: every crash cost a helper.
  EXPECT_EQ(pool.helpers_started(), 3u);
  EXPECT_TRUE(pool.quarantined(bad));
  EXPECT_FALSE(pool.quarantined(dir_ / "good.tx"));

  const uint64_t started = pool.helpers_started();
  constexpr int kRefusals = 20;
  Clock::duration slowest{0}, total{0};
  for (int i = 0; i < kRefusals; ++i) {
    const auto t0 = Clock::now();
    const Status s = decode(pool, "hostile-marker.tx", static_cast<uint32_t>(i % 7));
    const auto took = Clock::now() - t0;
    slowest = std::max(slowest, took);
    total += took;
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().code, ErrorCode::kCorrupt);
    EXPECT_TRUE(contains(s.error().message, bad)) << s.error().message;
    EXPECT_TRUE(contains(s.error().message, "quarantined after crashing the decode helper 2 times"))
        << s.error().message;
  }
  EXPECT_EQ(pool.helpers_started(), started) << "a quarantined file started a helper";
  // A refusal is a map look-up (microseconds); a helper start alone is tens of milliseconds (and none started,
  // above). The bound is on the mean so that one preemption on a loaded machine does not fail the test.
  EXPECT_LT(total / kRefusals, test::promptly(5ms));
  std::printf("quarantine refusals: mean %.1f us, slowest %.1f us\n",
              std::chrono::duration<double, std::micro>(total).count() / kRefusals,
              std::chrono::duration<double, std::micro>(slowest).count());

  // The good file still decodes on the helper that stayed.
  for (uint32_t level = 0; level < 7; ++level) ASSERT_TRUE(decode(pool, "good.tx", level).ok()) << level;
  EXPECT_EQ(pool.helpers_started(), started);
  const DecodeHelperPoolStats st = pool.stats();
  EXPECT_EQ(st.helper_failures, 2u);
  EXPECT_EQ(st.files_quarantined, 1u);
  EXPECT_EQ(st.quarantine_refusals, uint64_t{kRefusals});
}

TEST_F(DecodeQuarantineTest, AFileTheHelperRejectsIsCorruptButNeverQuarantined) {
  DecodeHelperPool pool(kHelper);
  const std::string garbage = (dir_ / "garbage.tx").string();
  for (int i = 0; i < 5; ++i) {
    const Status s = decode(pool, "garbage.tx");
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().code, ErrorCode::kCorrupt);
    EXPECT_TRUE(contains(s.error().message, garbage)) << s.error().message;
    EXPECT_FALSE(contains(s.error().message, "quarantined")) << s.error().message;
    // The intact file asked for at the wrong extent: also the helper's clean answer.
    Result<std::unique_ptr<StorageFile>> f = storage_.open(dir_ / "good.tx");
    ASSERT_TRUE(f.ok());
    std::vector<std::byte> big(128 * 128 * 4);
    uint64_t bytes_read = 0;
    const Status wrong = pool.decode(**f, dir_ / "good.tx", 0, Extent2D{128, 128}, big, bytes_read);
    ASSERT_FALSE(wrong.ok());
    EXPECT_FALSE(contains(wrong.error().message, "quarantined")) << wrong.error().message;
  }
  EXPECT_FALSE(pool.quarantined(garbage));
  EXPECT_FALSE(pool.quarantined(dir_ / "good.tx"));
  EXPECT_TRUE(decode(pool, "good.tx").ok());
  EXPECT_EQ(pool.helpers_started(), 1u) << "a clean error must keep the helper";
  const DecodeHelperPoolStats st = pool.stats();
  EXPECT_EQ(st.helper_failures, 0u);
  EXPECT_EQ(st.files_quarantined, 0u);
}

TEST_F(DecodeQuarantineTest, AFileThatHungTheHelperTwiceIsQuarantinedAndNeverStallsOtherDecodes) {
  ScopedEnv hook("TEXSTREAM_DECODE_HANG_ON", "hostile-marker");
  // Long enough that a good decode on a fresh helper (start-up included) on a busy machine stays below it:
  // 1 s was reached (2 of 6 runs, a build running beside). Each of the two hangs waits it out.
  constexpr auto kTimeout = test::promptly(500ms);
  DecodeHelperPool pool(kHelper, kTimeout);
  const std::string bad = (dir_ / "hostile-marker.tx").string();
  ASSERT_TRUE(decode(pool, "good.tx").ok());  // a warm helper for the good-file thread

  // One thread hangs helpers on the bad file while another decodes the good one: the good decodes go on.
  std::atomic<bool> hanging_done{false};
  std::vector<Status> hung;
  std::thread hanger([&] {
    for (int i = 0; i < 2; ++i) hung.push_back(decode(pool, "hostile-marker.tx"));
    hanging_done = true;
  });
  int good_during = 0;
  Clock::duration slowest_good{0};
  while (!hanging_done) {
    const auto t0 = Clock::now();
    const Status s = decode(pool, "good.tx", static_cast<uint32_t>(good_during % 7));
    slowest_good = std::max(slowest_good, Clock::now() - t0);
    EXPECT_TRUE(s.ok()) << s.error().message;
    if (!s.ok()) break;  // not ASSERT: the hanger thread must be joined
    ++good_during;
  }
  hanger.join();
  ASSERT_EQ(hung.size(), 2u);
  for (const Status& s : hung) {
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().code, ErrorCode::kTimeout);
    EXPECT_TRUE(contains(s.error().message, bad)) << s.error().message;
  }
  // Two hangs are at least 2 x 3 s: the good file was decoded many times meanwhile, none waiting a timeout.
  EXPECT_GE(good_during, 2);
  EXPECT_LT(slowest_good, kTimeout);
  std::printf("%d good decodes while two helpers hung; slowest %.1f ms\n", good_during,
              std::chrono::duration<double, std::milli>(slowest_good).count());

  EXPECT_TRUE(pool.quarantined(bad));
  const uint64_t started = pool.helpers_started();
  const auto t0 = Clock::now();
  const Status s = decode(pool, "hostile-marker.tx");
  EXPECT_LT(Clock::now() - t0, kTimeout / 4) << "a quarantined file waited for a helper";
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, ErrorCode::kCorrupt);
  EXPECT_TRUE(contains(s.error().message, "quarantined")) << s.error().message;
  EXPECT_EQ(pool.helpers_started(), started);
}

TEST_F(DecodeQuarantineTest, AHelperThatTimesOutBeforeReadingTheFileIsNotChargedToIt) {
  // A helper that never gets going (as one still loading its libraries on a loaded machine): its timeouts
  // are not the file's doing, however often.
  const fs::path slow = dir_ / "never-starts.sh";
  std::ofstream(slow) << "#!/bin/sh\nexec sleep 30\n";
  fs::permissions(slow, fs::perms::owner_all);
  DecodeHelperPool pool(slow, 200ms);
  for (int i = 0; i < 3; ++i) {
    const Status s = decode(pool, "good.tx");
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().code, ErrorCode::kTimeout);
    EXPECT_FALSE(contains(s.error().message, "quarantined")) << s.error().message;
  }
  EXPECT_FALSE(pool.quarantined(dir_ / "good.tx"));
  EXPECT_EQ(pool.stats().helper_failures, 0u);
  EXPECT_EQ(pool.helpers_started(), 3u);
}

// Through a whole Server (ServerHarness: real segment, real rings, the process's default helper pool): every
// mip of the crashing texture is answered with an error completion (never a stall), the log names its file
// and the quarantine, the other texture is served throughout, and the statistics count it.
TEST(ServerDecodeQuarantineTest, AServerAnswersACrashingTextureWithErrorsAndServesTheOthers) {
  const fs::path dir = fs::temp_directory_path() / ("texstream-quarantine-server-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  constexpr int64_t kWorkers = 2;
  const auto rgba = uint32_t(TexelFormat::kRgba8);
  const uint32_t mips = full_mip_count(64, 32);
  const std::vector<scene::TextureRecord> table = {{64, 32, mips, rgba}, {64, 32, mips, rgba}};
  ASSERT_TRUE(scene::write_texture_table(dir, table).ok());
  const fs::path good = texture_file_path(dir, TextureId(0), TextureFileKind::kTx);
  const fs::path bad = texture_file_path(dir, TextureId(1), TextureFileKind::kTx);
  make_tx(good);
  fs::create_directories(bad.parent_path());
  fs::copy_file(good, bad);
  ScopedEnv hook("TEXSTREAM_DECODE_CRASH_ON", bad.filename().string());

  std::ostringstream log;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(log);
  spdlog::default_logger()->sinks().push_back(sink);
  std::string stats;
  test::DriveResult result;
  std::vector<test::WantedMip> wanted;
  {
    // Every mip of both textures, the crashing one first so its crashes happen while the good one streams.
    for (uint32_t t : {1u, 0u}) {
      for (uint32_t m = 0; m < mips; ++m) wanted.push_back({t, m, 1.0f});
    }
    PosixStorage storage;
    ServerConfig config;
    config.idle_wait_ms = 5;
    config.worker_threads = kWorkers;
    std::string error;
    std::unique_ptr<test::ServerHarness> h = test::ServerHarness::start(dir, config, storage, error);
    ASSERT_TRUE(h) << error;
    result = test::drive(*h, wanted, test::kHangAfter, /*window=*/4);
    stats = h->server().stats_report();
  }
  spdlog::default_logger()->sinks().pop_back();
  const std::string text = log.str();
  fs::remove_all(dir);

  ASSERT_TRUE(result.complete) << "no final answer for some mips within 60 s";
  for (size_t i = 0; i < wanted.size(); ++i) {
    const auto status = static_cast<CompletionStatus>(result.status[i]);
    if (wanted[i].texture == 0) {
      EXPECT_EQ(status, CompletionStatus::kOk) << "good texture mip " << wanted[i].mip;
    } else {
      EXPECT_EQ(status, CompletionStatus::kCorrupt) << "crashing texture mip " << wanted[i].mip;
    }
  }
  EXPECT_TRUE(contains(text, bad.string())) << text;
  // fmt, not operator+: GCC 12 -O3 warns falsely (-Wrestrict) on that concatenation.
  EXPECT_TRUE(contains(text, fmt::format("'{}' quarantined", bad.string()))) << text;
  // The refusals name the crash count when the file was quarantined: 2, or more when other workers' decodes
  // of it were already under way and crashed too (seen under ASan: "3 times").
  bool count_named = false;
  for (uint32_t n = 2; n <= kWorkers + 1; ++n) {
    count_named =
        count_named || contains(text, fmt::format("quarantined after crashing the decode helper {} times", n));
  }
  EXPECT_TRUE(count_named) << text;
  EXPECT_FALSE(contains(text, good.string())) << text;
  // Two crashes, then every other mip of texture 1 refused without a helper. With two workers a third
  // decode of it may already be under way when the second crash quarantines it, so 2 or 3 crashes.
  const std::optional<DecodeHelperPoolStats> st = default_decode_helper_pool_stats();
  ASSERT_TRUE(st.has_value());
  EXPECT_GE(st->helper_failures, 2u);
  EXPECT_LE(st->helper_failures, uint64_t{kWorkers} + 1);  // 2 + the other workers' decodes then under way
  EXPECT_EQ(st->files_quarantined, 1u);
  EXPECT_EQ(st->helper_failures + st->quarantine_refusals, uint64_t{mips});
  EXPECT_TRUE(contains(stats, "decode helpers:")) << stats;
  EXPECT_TRUE(contains(stats, "1 files quarantined")) << stats;
  std::printf("%s\n", stats.c_str());
}

// The server-process level (stream_client.hpp): each load worker records the texture it is working on in
// ServerBlock::loading (texture id + 1) and clears it after, so that the renderer can charge a crash to it.
TEST(WorkerPoolLoadingWords, EachWorkerRecordsTheTextureItIsLoadingAndClearsItAfter) {
  std::array<ShmAtomic<uint32_t>, kLoadingWords> words{};
  std::mutex m;
  std::condition_variable cv;
  int working = 0;
  bool release = false;
  std::atomic<int> results{0};
  {
    WorkerPool pool(
        2,
        [&](const LoadJob& job) {
          std::unique_lock lock(m);
          ++working;
          cv.notify_all();
          cv.wait(lock, [&] { return release; });
          CompletionRecord c{};
          c.texture_id = job.request.texture.value;
          return c;
        },
        [&] { results.fetch_add(1); }, std::span(words).first(2));
    for (uint32_t texture : {7u, 9u}) {
      LoadJob job{};
      job.request.texture = TextureId(texture);
      pool.submit(job);
    }
    {
      std::unique_lock lock(m);
      // EXPECT, not ASSERT: the workers must be released below whatever happens, or the pool never joins.
      EXPECT_TRUE(cv.wait_for(lock, test::kHangAfter, [&] { return working == 2; }));
    }
    // Both jobs are inside the work function: each worker's word names its texture (+1).
    const std::set<uint32_t> seen{words[0].v.load(), words[1].v.load()};
    EXPECT_EQ(seen, (std::set<uint32_t>{8u, 10u}));
    for (size_t i = 2; i < words.size(); ++i) EXPECT_EQ(words[i].v.load(), 0u) << "word " << i << " not given";
    {
      std::lock_guard lock(m);
      release = true;
    }
    cv.notify_all();
    const auto end = Clock::now() + test::kHangAfter;
    while (results.load() < 2 && Clock::now() < end) std::this_thread::sleep_for(1ms);
    ASSERT_EQ(results.load(), 2);
  }  // joined: every store made
  EXPECT_EQ(words[0].v.load(), 0u);
  EXPECT_EQ(words[1].v.load(), 0u);
}

// Issue 27: a slow first decode must never look like a hang. The dispatcher loads small misses itself, but a
// texture that needs a decode (here a tiled TIFF whose helper hangs: TEXSTREAM_DECODE_HANG_ON, until the helper
// pool's timeout kills it) goes to a worker the moment its header says so, and the raw DDS texture asked after it
// is served while the decode still hangs: every one of its mips is answered before the hung texture's answer.
// With the decode on the dispatcher, the hung answer came first and the raw mips only after it. (Order, not
// time: the test holds on a machine of any speed.)
TEST(ServerDecodeOffTheDispatcher, AHungDecodeNeverHoldsUpTheMipsQueuedBehindIt) {
  const fs::path dir = fs::temp_directory_path() / ("texstream-decode-offload-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const auto rgba = uint32_t(TexelFormat::kRgba8);
  const uint32_t mips = full_mip_count(64, 32);
  const std::vector<scene::TextureRecord> table = {{64, 32, mips, rgba}, {64, 32, mips, rgba}};
  ASSERT_TRUE(scene::write_texture_table(dir, table).ok());
  const fs::path hung = texture_file_path(dir, TextureId(0), TextureFileKind::kTx);
  make_tx(hung);
  {  // texture 1: a raw RGBA8 DDS, served without a decode
    const fs::path dds = scene::texture_path(dir, TextureId(1));
    fs::create_directories(dds.parent_path());
    std::ofstream out(dds, std::ios::binary);
    const auto header = scene::make_dds_header(TexelFormat::kRgba8, 64, 32, mips);
    out.write(reinterpret_cast<const char*>(header.data()), static_cast<std::streamsize>(header.size()));
    const std::vector<char> texels(mip_chain_offset(TexelFormat::kRgba8, 64, 32, mips), 'x');
    out.write(texels.data(), static_cast<std::streamsize>(texels.size()));
  }
  ScopedEnv hook("TEXSTREAM_DECODE_HANG_ON", hung.filename().string());

  PosixStorage storage;
  ServerConfig config;
  config.idle_wait_ms = 5;
  config.worker_threads = 2;
  std::string error;
  std::vector<uint32_t> answered;  // texture ids in the order of their final answers
  {
    std::unique_ptr<test::ServerHarness> h = test::ServerHarness::start(dir, config, storage, error);
    ASSERT_TRUE(h) << error;
    // The hung texture's coarsest mip first (small: the dispatcher would load it inline), then every mip of the
    // raw one, in one batch.
    auto ask = [&](uint32_t texture, uint32_t mip) {
      ASSERT_TRUE(h->push(texture, mip, 1, texture == 0 ? 100.0f : 1.0f));
    };
    ask(0, mips - 1);
    for (uint32_t m = 0; m < mips; ++m) ask(1, m);
    h->ring();
    const auto give_up = Clock::now() + test::kHangAfter;
    while (answered.size() < mips + 1 && Clock::now() < give_up) {
      h->poll([&](const CompletionRecord& c, std::span<const std::byte>) {
        const auto status = static_cast<CompletionStatus>(c.status);
        if (status == CompletionStatus::kUnfilled || status == CompletionStatus::kCancelled) {
          ask(c.texture_id, c.mip_level);  // asked again, as the renderer would
          h->ring();
          return;
        }
        answered.push_back(c.texture_id);
      });
      std::this_thread::sleep_for(1ms);
    }
  }
  fs::remove_all(dir);
  ASSERT_EQ(answered.size(), mips + 1) << "not every mip was answered within " << test::kHangAfter.count() << " s";
  const auto hung_answer = std::find(answered.begin(), answered.end(), 0u);
  EXPECT_EQ(std::count(answered.begin(), hung_answer, 1u), static_cast<long>(mips))
      << "raw mips answered only after the hung decode's answer: the decode held up the dispatcher";
}

}  // namespace
}  // namespace texstream::server
