// The Server in this process over a real shared segment; the test plays the renderer: it pushes requests,
// polls completions, checks the payload bytes against the files it wrote, and releases slots.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <thread>
#include <vector>

#include "../support/patience.hpp"
#include "texstream/common/dds.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/checksum.hpp"
#include "texstream/protocol/doorbell.hpp"
#include "texstream/protocol/liveness.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/server/dispatch/server.hpp"
#include "texstream/server/storage/posix_storage.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;

namespace texstream::server {
namespace {

// The scene every test streams from.
enum Tex : uint32_t {
  kRgbaA = 0,      // 64x64 RGBA8
  kBc1 = 1,        // 32x16 BC1
  kRgbaB = 2,      // 128x128 RGBA8
  kMissing = 3,    // 8x8 BC1, no file
  kTruncated = 4,  // 64x64 RGBA8, file cut inside mip 2
  kMismatch = 5,   // 16x16 RGBA8 in the table, 32x32 in the DDS header
  kFaulty = 6,     // 16x16 RGBA8; FaultyStorage fails its reads
  kTextureCount = 7,
};

std::byte pattern(uint32_t texture, uint64_t i) {
  uint64_t x = (uint64_t{texture} << 40) ^ (i * 0x9e3779b97f4a7c15ull);
  x ^= x >> 29;
  return static_cast<std::byte>(x & 0xff);
}

// Storage that fails every read of one path: tests that an I/O error is answered and others still served.
class FaultyStorage final : public Storage {
 public:
  explicit FaultyStorage(fs::path bad) : bad_(std::move(bad)) {}
  Result<std::unique_ptr<StorageFile>> open(const fs::path& path) override {
    auto f = inner_.open(path);
    if (!f.ok() || path != bad_) return f;
    return std::unique_ptr<StorageFile>(new Failing());
  }

 private:
  struct Failing final : StorageFile {
    Result<uint64_t> read_at(std::span<std::byte>, uint64_t) override {
      return make_error(ErrorCode::kIo, "injected I/O error");
    }
    Result<uint64_t> size() override { return make_error(ErrorCode::kIo, "injected I/O error"); }
  };
  PosixStorage inner_;
  fs::path bad_;
};

class ServerStreamingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    static int counter = 0;
    name_ = "texstream-srvtest-" + std::to_string(getpid()) + "-" + std::to_string(counter++);
    dir_ = fs::temp_directory_path() / name_;
    fs::create_directories(dir_);
    write_scene();
  }

  void TearDown() override {
    stop_server();
    fs::remove_all(dir_);
  }

  void write_scene() {
    const scene::TextureRecord table[kTextureCount] = {
        {64, 64, full_mip_count(64, 64), uint32_t(TexelFormat::kRgba8)},
        {32, 16, full_mip_count(32, 16), uint32_t(TexelFormat::kBc1)},
        {128, 128, full_mip_count(128, 128), uint32_t(TexelFormat::kRgba8)},
        {8, 8, full_mip_count(8, 8), uint32_t(TexelFormat::kBc1)},
        {64, 64, full_mip_count(64, 64), uint32_t(TexelFormat::kRgba8)},
        {16, 16, full_mip_count(16, 16), uint32_t(TexelFormat::kRgba8)},
        {16, 16, full_mip_count(16, 16), uint32_t(TexelFormat::kRgba8)},
    };
    table_.assign(std::begin(table), std::end(table));
    ASSERT_TRUE(scene::write_texture_table(dir_, table_).ok());
    for (uint32_t t = 0; t < kTextureCount; ++t) {
      if (t == kMissing) continue;
      const scene::TextureRecord& r = table_[t];
      const auto format = static_cast<TexelFormat>(r.format);
      const uint32_t header_w = t == kMismatch ? 32 : r.width, header_h = t == kMismatch ? 32 : r.height;
      const auto header = scene::make_dds_header(format, header_w, header_h, full_mip_count(header_w, header_h));
      std::vector<std::byte> payload(scene::dds_file_bytes(format, r.width, r.height, r.mip_count) -
                                     scene::kDdsHeaderBytes);
      for (uint64_t i = 0; i < payload.size(); ++i) payload[i] = pattern(t, i);
      if (t == kTruncated) payload.resize(mip_chain_offset(format, r.width, r.height, 2) + 100);
      payloads_[t] = payload;
      const fs::path path = scene::texture_path(dir_, TextureId(t));
      fs::create_directories(path.parent_path());
      std::ofstream f(path, std::ios::binary);
      f.write(reinterpret_cast<const char*>(header.data()), header.size());
      f.write(reinterpret_cast<const char*>(payload.data()), static_cast<std::streamsize>(payload.size()));
      ASSERT_TRUE(f.good());
    }
  }

  void create_segment(SegmentParams params) {
    auto seg = Segment::create(name_, params);
    ASSERT_TRUE(seg.ok()) << seg.error().message;
    segment_ = std::move(seg).value();
    requests_ = segment_->request_producer();
    completions_ = segment_->completion_consumer();
  }

  void start_server(ServerConfig config = {}, Storage* storage = nullptr) {
    if (!segment_) create_segment({});
    config.idle_wait_ms = 5;
    auto server = Server::create(*segment_, dir_, config, storage ? *storage : posix_);
    ASSERT_TRUE(server.ok()) << server.error().message;
    server_ = std::move(server).value();
    thread_ = std::thread([this] { outcome_ = server_->run(stop_); });
  }

  void stop_server() {
    if (!thread_.joinable()) return;
    stop_ = true;
    Doorbell(*segment_).wake_all();
    thread_.join();
    EXPECT_EQ(outcome_, RunOutcome::kStopped);
    EXPECT_EQ(segment_->server_block().attached.v.load(), 0u);
  }

  // The renderer's side of the doorbell protocol.
  void ring_doorbell() { Doorbell(*segment_).ring(); }

  void push(const RequestRecord& r) {
    const auto deadline = std::chrono::steady_clock::now() + test::kHangAfter;
    while (!requests_.try_push(r)) {
      ASSERT_LT(std::chrono::steady_clock::now(), deadline) << "request ring stayed full";
      std::this_thread::sleep_for(1ms);
    }
    ring_doorbell();
  }
  void load(uint32_t texture, uint32_t mip, uint64_t generation = 1, float priority = 1) {
    RequestRecord r{};
    r.kind = static_cast<uint32_t>(RequestKind::kLoad);
    r.texture_id = texture;
    r.mip_level = mip;
    r.generation = generation;
    r.priority = priority;
    push(r);
  }
  void release(uint32_t slot) {
    RequestRecord r{};
    r.kind = static_cast<uint32_t>(RequestKind::kReleaseSlot);
    r.slot = slot;
    push(r);
  }

  std::optional<CompletionRecord> next(std::chrono::milliseconds timeout = test::kHangAfter) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      if (auto c = completions_.try_pop()) return c;
      if (std::chrono::steady_clock::now() >= deadline) return std::nullopt;
      std::this_thread::sleep_for(200us);
    }
  }
  std::vector<CompletionRecord> next_n(size_t n) {
    std::vector<CompletionRecord> out;
    while (out.size() < n) {
      auto c = next();
      if (!c) {
        ADD_FAILURE() << "timed out after " << out.size() << " of " << n << " completions";
        break;
      }
      out.push_back(*c);
    }
    return out;
  }

  // Checks a kOk completion against the bytes written for that mip.
  void expect_payload(const CompletionRecord& c) {
    ASSERT_EQ(c.status, uint32_t(CompletionStatus::kOk)) << to_string(CompletionStatus(c.status));
    ASSERT_LT(c.slot, segment_->slot_count());
    const scene::TextureRecord& r = table_.at(c.texture_id);
    const auto format = static_cast<TexelFormat>(r.format);
    const Extent2D e = mip_extent(r.width, r.height, c.mip_level);
    EXPECT_EQ(c.format, r.format);
    EXPECT_EQ(c.width, e.width);
    EXPECT_EQ(c.height, e.height);
    const uint64_t bytes = mip_bytes(format, e);
    ASSERT_EQ(c.byte_size, bytes);
    const uint64_t offset = mip_chain_offset(format, r.width, r.height, c.mip_level);
    const std::vector<std::byte>& file = payloads_.at(c.texture_id);
    ASSERT_LE(offset + bytes, file.size());
    const std::span<std::byte> slot = segment_->slot(c.slot);
    EXPECT_EQ(std::memcmp(slot.data(), file.data() + offset, bytes), 0)
        << "texture " << c.texture_id << " mip " << c.mip_level;
    EXPECT_EQ(c.checksum, payload_checksum(file.data() + offset, bytes));
  }

  ServerBlock& stats() { return segment_->server_block(); }

  std::string name_;
  fs::path dir_;
  std::vector<scene::TextureRecord> table_;
  std::map<uint32_t, std::vector<std::byte>> payloads_;
  std::unique_ptr<Segment> segment_;
  SpscRingProducer<RequestRecord> requests_;
  SpscRingConsumer<CompletionRecord> completions_;
  PosixStorage posix_;
  std::unique_ptr<Server> server_;
  std::atomic<bool> stop_{false};
  RunOutcome outcome_ = RunOutcome::kPeerCorrupt;
  std::thread thread_;
};

TEST_F(ServerStreamingTest, StreamsEveryMipOfRgbaAndBc1Exactly) {
  start_server();
  for (uint32_t t : {uint32_t{kRgbaA}, uint32_t{kBc1}}) {
    for (uint32_t mip = 0; mip < table_[t].mip_count; ++mip) {
      load(t, mip, 3);
      auto c = next();
      ASSERT_TRUE(c);
      EXPECT_EQ(c->texture_id, t);
      EXPECT_EQ(c->mip_level, mip);
      EXPECT_EQ(c->generation, 3u);
      expect_payload(*c);
      release(c->slot);
    }
  }
  EXPECT_EQ(stats().attached.v.load(), 1u);
  EXPECT_EQ(stats().pid.v.load(), static_cast<uint32_t>(getpid()));
  EXPECT_EQ(stats().completions.v.load(), 7u + 6u);
  // Only headers + exact mip ranges were read: each texture's header once (the file index remembers the
  // layout) and the two full chains. Each texture's first load reads its whole chain from mip 0, so its
  // 128-byte legacy header comes along in the same read (MipLoader's guessed layout, confirmed by it).
  const uint64_t chains =
      mip_chain_offset(TexelFormat::kRgba8, 64, 64, 7) + mip_chain_offset(TexelFormat::kBc1, 32, 16, 6);
  EXPECT_EQ(stats().bytes_read.v.load(), 2 * scene::kDdsHeaderBytes + chains);
  EXPECT_GT(stats().heartbeat.v.load(), 0u);
}

TEST_F(ServerStreamingTest, RepeatedRequestIsARamCacheHitThatReadsNothing) {
  start_server();
  load(kRgbaB, 0);
  auto first = next();
  ASSERT_TRUE(first);
  expect_payload(*first);
  release(first->slot);
  const uint64_t read_after_first = stats().bytes_read.v.load();
  EXPECT_EQ(read_after_first, scene::kDdsMaxHeaderBytes + 128 * 128 * 4);
  EXPECT_EQ(stats().ram_cache_misses.v.load(), 1u);
  EXPECT_EQ(stats().ram_cache_hits.v.load(), 0u);
  load(kRgbaB, 0, 2);
  auto second = next();
  ASSERT_TRUE(second);
  expect_payload(*second);
  EXPECT_EQ(second->generation, 2u);
  EXPECT_EQ(stats().ram_cache_hits.v.load(), 1u);
  EXPECT_EQ(stats().ram_cache_misses.v.load(), 1u);
  EXPECT_EQ(stats().bytes_read.v.load(), read_after_first);
  EXPECT_EQ(server_->cache_stats().hits, 1u);
}

TEST_F(ServerStreamingTest, LevelPolicyServesExactlyAndKeepsTheBudget) {
  ServerConfig config;
  config.cache_policy = RamCachePolicy::kLevel;
  config.ram_cache_bytes = 40'000;  // less than texture kRgbaB's chain (87 380 bytes): evictions happen
  start_server(config);
  for (int round = 0; round < 2; ++round) {
    for (uint32_t t : {uint32_t{kRgbaA}, uint32_t{kRgbaB}, uint32_t{kBc1}}) {
      for (uint32_t mip = table_[t].mip_count; mip-- > 0;) {
        load(t, mip, 10 + static_cast<uint64_t>(round));
        auto c = next();
        ASSERT_TRUE(c);
        expect_payload(*c);
        release(c->slot);
        ASSERT_LE(server_->cache_stats().bytes, 40'000u);
      }
    }
  }
  const MipCacheStats s = server_->cache_stats();
  EXPECT_GT(s.evictions, 0u);
  EXPECT_GT(s.hits, 0u);
}

// An unknown server.cache_policy cannot reach Server::create any more: the config parser refuses it naming the
// key (config_test.cpp, Config.AChoiceKeyTakesOnlyItsNames).

TEST_F(ServerStreamingTest, ZeroCacheBudgetReadsAgain) {
  ServerConfig config;
  config.ram_cache_bytes = 0;
  start_server(config);
  for (int i = 0; i < 2; ++i) {
    load(kRgbaA, 1);
    auto c = next();
    ASSERT_TRUE(c);
    expect_payload(*c);
    release(c->slot);
  }
  EXPECT_EQ(stats().ram_cache_hits.v.load(), 0u);
  EXPECT_EQ(stats().ram_cache_misses.v.load(), 2u);
}

TEST_F(ServerStreamingTest, NewerGenerationCancelsPendingOlderRequests) {
  SegmentParams params;
  params.slot_count = 2;
  create_segment(params);
  // Cycle 1 is in the ring before the server starts, so it is read as one batch: the two best start at
  // once (two slots), the other four wait for a slot.
  for (uint32_t mip = 0; mip < 6; ++mip) load(kRgbaB, mip, 1, static_cast<float>(10 - mip));
  start_server();
  const auto started = next_n(2);
  ASSERT_EQ(started.size(), 2u);
  for (const auto& c : started) {
    expect_payload(c);
    EXPECT_LT(c.mip_level, 2u) << "the two highest priorities go first";
  }
  // Cycle 2 asks again for mip 3 and for something new; mips 2, 4, 5 are not asked for any more.
  load(kRgbaB, 3, 2, 1);
  load(kBc1, 0, 2, 1);
  const auto cancelled = next_n(4);
  std::vector<uint32_t> cancelled_mips;
  for (const auto& c : cancelled) {
    EXPECT_EQ(c.status, uint32_t(CompletionStatus::kCancelled));
    EXPECT_EQ(c.slot, kNoSlot);
    EXPECT_EQ(c.generation, 1u);
    EXPECT_EQ(c.texture_id, uint32_t{kRgbaB});
    cancelled_mips.push_back(c.mip_level);
  }
  std::sort(cancelled_mips.begin(), cancelled_mips.end());
  EXPECT_EQ(cancelled_mips, (std::vector<uint32_t>{2, 3, 4, 5}));  // 3's cycle-1 request lives on as cycle 2
  EXPECT_FALSE(next(50ms)) << "nothing else may complete while both slots are the renderer's";
  for (const auto& c : started) release(c.slot);
  const auto rest = next_n(2);
  for (const auto& c : rest) {
    expect_payload(c);
    EXPECT_EQ(c.generation, 2u);
  }
  EXPECT_EQ(stats().requests_cancelled.v.load(), 4u);
  EXPECT_EQ(stats().requests_received.v.load(), 8u);
  EXPECT_EQ(stats().completions.v.load(), 8u);
}

TEST_F(ServerStreamingTest, DuplicateInOneBatchIsAnsweredOnce) {
  create_segment({});
  load(kBc1, 1, 1, 1);
  load(kBc1, 1, 1, 5);
  start_server();
  const auto done = next_n(2);
  ASSERT_EQ(done.size(), 2u);
  int ok = 0, cancelled = 0;
  for (const auto& c : done) {
    if (c.status == uint32_t(CompletionStatus::kOk)) {
      expect_payload(c);
      ++ok;
    } else {
      EXPECT_EQ(c.status, uint32_t(CompletionStatus::kCancelled));
      ++cancelled;
    }
  }
  EXPECT_EQ(ok, 1);
  EXPECT_EQ(cancelled, 1);
}

TEST_F(ServerStreamingTest, BadFilesGiveErrorCompletionsAndOthersAreStillServed) {
  start_server();
  load(kMissing, 0);
  load(kTruncated, 3);  // lies past the cut
  load(kTruncated, 0);  // lies before it
  load(kMismatch, 0);
  load(kRgbaA, 2);
  const auto K = [](uint32_t t, uint32_t m) { return std::pair<uint32_t, uint32_t>(t, m); };
  std::map<std::pair<uint32_t, uint32_t>, CompletionRecord> by_key;
  for (const auto& c : next_n(5)) by_key[{c.texture_id, c.mip_level}] = c;
  ASSERT_EQ(by_key.size(), 5u);
  EXPECT_EQ(by_key[K(kMissing, 0)].status, uint32_t(CompletionStatus::kNotFound));
  EXPECT_EQ(by_key[K(kMissing, 0)].slot, kNoSlot);
  EXPECT_EQ(by_key[K(kTruncated, 3)].status, uint32_t(CompletionStatus::kCorrupt));
  EXPECT_EQ(by_key[K(kTruncated, 3)].slot, kNoSlot);
  expect_payload(by_key[K(kTruncated, 0)]);
  EXPECT_EQ(by_key[K(kMismatch, 0)].status, uint32_t(CompletionStatus::kCorrupt));
  expect_payload(by_key[K(kRgbaA, 2)]);
  // The failed loads gave their slots back: all but the two kOk ones are free for more work.
  for (uint32_t mip = 0; mip < 7; ++mip) load(kRgbaA, mip, 2);
  for (const auto& c : next_n(7)) expect_payload(c);
}

// A FIFO or a directory where a texture file should be. A FIFO used to block the dispatcher's open() until a
// writer came: the renderer killed the hung server, started another, which hung on the same file, for ever.
// Now both are answered with an error at once, and the server goes on serving.
TEST_F(ServerStreamingTest, AFifoOrADirectoryInPlaceOfATextureFileIsAnErrorNotAHang) {
  const fs::path fifo = scene::texture_path(dir_, TextureId(kMissing));
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0) << std::strerror(errno);
  const fs::path folder = scene::texture_path(dir_, TextureId(kFaulty));
  fs::remove(folder);
  fs::create_directory(folder);
  start_server();
  load(kMissing, 0);
  load(kFaulty, 0);
  load(kRgbaA, 1);
  std::map<uint32_t, CompletionRecord> by_texture;
  for (const auto& c : next_n(3)) by_texture[c.texture_id] = c;
  // On a failure above the dispatcher may still sit in open(): a writer lets it go, so the test ends.
  if (const int w = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK); w >= 0) ::close(w);
  ASSERT_EQ(by_texture.size(), 3u);
  // kCorrupt, which the renderer does not ask again for (it was kIoError: 4 asks per texture).
  for (const uint32_t t : {uint32_t(kMissing), uint32_t(kFaulty)}) {
    EXPECT_EQ(by_texture[t].status, uint32_t(CompletionStatus::kCorrupt))
        << "texture " << t << ": " << to_string(static_cast<CompletionStatus>(by_texture[t].status));
    EXPECT_EQ(by_texture[t].slot, kNoSlot) << "texture " << t;
  }
  expect_payload(by_texture[kRgbaA]);
  EXPECT_EQ(server_->stats().corrupt.load(), 2u);
  EXPECT_EQ(server_->stats().io_errors.load(), 0u);
}

// Local misses are loaded by the dispatcher itself (inline) whatever the number of threads: with 8 workers and
// 4 remote fetchers every crash-attribution word used to be taken before the dispatcher's, so no miss was
// loaded inline and every one went through a worker hand-off.
TEST_F(ServerStreamingTest, ManyWorkersStillLoadLocalMissesInline) {
  ServerConfig config;
  config.worker_threads = 8;
  config.remote_fetches_in_flight = 4;
  start_server(config);
  for (uint32_t mip = 0; mip < 7; ++mip) load(kRgbaA, mip);
  for (const auto& c : next_n(7)) expect_payload(c);
  EXPECT_EQ(server_->stats().in_flight.max.load(), 0u) << "a miss went to a worker";
  EXPECT_GT(server_->stats().loads_ok.load(), 0u);
}

TEST_F(ServerStreamingTest, StorageErrorIsAnIoErrorCompletion) {
  FaultyStorage faulty(scene::texture_path(dir_, TextureId(kFaulty)));
  start_server({}, &faulty);
  load(kFaulty, 0);
  load(kRgbaA, 0);
  std::map<uint32_t, CompletionRecord> by_texture;
  for (const auto& c : next_n(2)) by_texture[c.texture_id] = c;
  EXPECT_EQ(by_texture[kFaulty].status, uint32_t(CompletionStatus::kIoError));
  expect_payload(by_texture[kRgbaA]);
}

TEST_F(ServerStreamingTest, SlotExhaustionWaitsAndServesEverything) {
  SegmentParams params;
  params.slot_count = 2;
  create_segment(params);
  start_server();
  for (uint32_t mip = 0; mip < 7; ++mip) load(kRgbaA, mip, 1, static_cast<float>(mip));
  for (uint32_t mip = 0; mip < 3; ++mip) load(kBc1, mip, 1, 0.5f);
  int served = 0;
  while (served < 10) {
    auto c = next();
    ASSERT_TRUE(c) << "stalled after " << served << " completions";
    expect_payload(*c);
    ++served;
    release(c->slot);  // the renderer hands each slot back once it has uploaded it
  }
  EXPECT_EQ(stats().completions.v.load(), 10u);
}

TEST_F(ServerStreamingTest, FullCompletionRingQueuesInsteadOfDropping) {
  SegmentParams params;
  params.completion_capacity = 4;
  params.slot_count = 16;
  create_segment(params);
  start_server();
  for (uint32_t mip = 0; mip < 7; ++mip) load(kRgbaA, mip);
  for (uint32_t mip = 0; mip < 3; ++mip) load(kBc1, mip);
  // The server fills the ring (however slowly a sanitized build on a busy machine gets there), then must queue
  // the rest: the count stays at the ring's capacity until the renderer reads.
  const auto give_up = std::chrono::steady_clock::now() + test::kHangAfter;
  while (stats().completions.v.load() < 4u && std::chrono::steady_clock::now() < give_up)
    std::this_thread::sleep_for(5ms);
  std::this_thread::sleep_for(100ms);
  EXPECT_EQ(stats().completions.v.load(), 4u);
  std::vector<CompletionRecord> all = next_n(10);
  for (const auto& c : all) expect_payload(c);
  EXPECT_EQ(stats().completions.v.load(), 10u);
}

TEST_F(ServerStreamingTest, InvalidRecordsAreDroppedAndServingGoesOn) {
  start_server();
  RequestRecord bad{};
  bad.kind = 99;
  push(bad);
  release(1);        // the renderer does not own slot 1
  release(100000);   // no such slot
  load(1000, 0);     // texture id out of range
  load(kRgbaA, 40);  // mip out of range
  RequestRecord nan_priority{};
  nan_priority.kind = static_cast<uint32_t>(RequestKind::kLoad);
  nan_priority.texture_id = kRgbaA;
  nan_priority.priority = std::numeric_limits<float>::quiet_NaN();
  push(nan_priority);
  load(kBc1, 2);
  auto c = next();
  ASSERT_TRUE(c);
  EXPECT_EQ(c->texture_id, uint32_t{kBc1});
  expect_payload(*c);
  EXPECT_FALSE(next(50ms)) << "invalid records get no completion";
  EXPECT_EQ(stats().requests_received.v.load(), 1u);
  // A release of the slot just handed over is valid; a second one is not and changes nothing.
  release(c->slot);
  release(c->slot);
  load(kBc1, 3);
  auto d = next();
  ASSERT_TRUE(d);
  expect_payload(*d);
}

TEST_F(ServerStreamingTest, MipLargerThanASlotIsAnErrorNotACrash) {
  SegmentParams params;
  params.slot_bytes = 4096;  // 128x128 RGBA8 mip 0 is 64 KiB
  create_segment(params);
  start_server();
  load(kRgbaB, 0);
  load(kRgbaB, 5);  // 4x4: fits
  std::map<uint32_t, CompletionRecord> by_mip;
  for (const auto& c : next_n(2)) by_mip[c.mip_level] = c;
  EXPECT_EQ(by_mip[0].status, uint32_t(CompletionStatus::kIoError));
  expect_payload(by_mip[5]);
}

TEST_F(ServerStreamingTest, CorruptRingPositionEndsTheRun) {
  start_server();
  load(kRgbaA, 0);
  ASSERT_TRUE(next());
  // A hostile renderer publishes an impossible write position.
  segment_->request_control()->write_pos.v.store(1u << 30, std::memory_order_release);
  ring_doorbell();
  thread_.join();
  EXPECT_EQ(outcome_, RunOutcome::kPeerCorrupt);
  EXPECT_EQ(stats().attached.v.load(), 0u);
}

}  // namespace
}  // namespace texstream::server
