// Issue 9, the hostile server: a fake texstream-server in a thread (opening the segment by name as the real one
// does) that answers with garbage records, out-of-range slots and sizes, wrong shapes, generations and
// textures, duplicates and stalls, while a second thread scribbles over the staging slots and the completion
// records — changing values between the client's read and its checks, and payload bytes during its copy.
// The client must commit only payloads that are exactly right, never read outside the segment (run this
// under ASan: scripts/ci_sanitizers.sh), never hang, and keep working once the server behaves again.
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <random>
#include <thread>
#include <vector>

#include "../support/patience.hpp"
#include "chaos_test_support.hpp"
#include "texstream/protocol/checksum.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/stream/stream_client.hpp"

namespace texstream {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

std::vector<TextureShape> shapes() {
  return {{64, 64, 7, TexelFormat::kRgba8}, {128, 32, 8, TexelFormat::kRgba8}, {256, 256, 9, TexelFormat::kBc1}};
}

std::byte pattern(uint32_t texture, uint32_t mip, uint64_t i) {
  return static_cast<std::byte>((texture * 31u + mip * 7u + i * 13u + (i >> 8)) & 0xffu);
}

Config config(const std::string& segment) {
  Config c;
  c.protocol.segment_name = segment;
  c.protocol.request_ring_capacity = 64;
  c.protocol.completion_ring_capacity = 64;
  c.protocol.staging_slot_count = 8;
  c.protocol.staging_slot_bytes = 64 << 10;
  c.cache.layer_extent_px = 64;
  c.stream.max_requests_in_flight = 16;
  return c;
}

// Commits must be exactly the pattern; everything else is counted.
class VerifyingSink : public stream::MipSink {
 public:
  std::span<std::byte> reserve(TextureId, MipLevel, uint64_t bytes) override {
    buffer_.assign(bytes, std::byte{0});
    return buffer_;
  }
  void commit(TextureId t, MipLevel m, std::span<std::byte> data) override {
    const auto s = shapes().at(t.value);
    bool ok = data.size() == mip_bytes(s.format, s.width, s.height, m.value);
    for (uint64_t i = 0; ok && i < data.size(); ++i) ok = data[i] == pattern(t.value, m.value, i);
    ++(ok ? good_commits : bad_commits);
  }
  void reject(TextureId, MipLevel, std::span<std::byte>) override { ++rejects; }
  void failed(TextureId, MipLevel, CompletionStatus) override { ++failures; }
  uint64_t good_commits = 0, bad_commits = 0, rejects = 0, failures = 0;

 private:
  std::vector<std::byte> buffer_;
};

class HostileServer {
 public:
  HostileServer(const std::string& name, uint64_t seed) : rng_(seed) {
    auto seg = Segment::open(name);
    EXPECT_TRUE(seg.ok()) << (seg.ok() ? "" : seg.error().message);
    seg_ = std::move(*seg);
    requests_ = seg_->request_consumer();
    completions_ = seg_->completion_producer();
    seg_->server_block().attached.v.store(1);
  }

  // Serves until `stop`: every load gets one of the attacks (or, 1 in 4, a correct answer).
  void run(const std::atomic<bool>& stop) {
    const uint32_t slots = seg_->slot_count();
    uint32_t next_slot = 0;
    while (!stop.load()) {
      seg_->server_block().heartbeat.v.fetch_add(1);
      auto r = requests_.try_pop();
      if (!r) {
        std::this_thread::sleep_for(100us);
        continue;
      }
      if (r->kind != static_cast<uint32_t>(RequestKind::kLoad) || r->texture_id >= shapes().size()) continue;
      const TextureShape s = shapes()[r->texture_id];
      const Extent2D e = mip_extent(s.width, s.height, r->mip_level);
      const uint64_t bytes = mip_bytes(s.format, e);
      const uint32_t slot = next_slot++ % slots;  // ignores ownership on purpose
      std::span<std::byte> dst = seg_->slot(slot);
      // The checksum is of the bytes the server means to send, computed before they reach the slot: a flip by
      // the scribbler between fill and checksum would otherwise make a consistent lie that no receiver can
      // detect (the checksum guards against changes after publication, not against a server lying about both).
      const uint64_t n = std::min<uint64_t>(bytes, dst.size());
      intended_.resize(n);
      for (uint64_t i = 0; i < n; ++i) intended_[i] = pattern(r->texture_id, r->mip_level, i);
      std::memcpy(dst.data(), intended_.data(), n);
      CompletionRecord c{};
      c.status = static_cast<uint32_t>(CompletionStatus::kOk);
      c.request_kind = static_cast<uint32_t>(RequestKind::kLoad);
      c.slot = slot;
      c.texture_id = r->texture_id;
      c.mip_level = r->mip_level;
      c.generation = r->generation;
      c.byte_size = bytes;
      c.format = static_cast<uint32_t>(s.format);
      c.width = e.width;
      c.height = e.height;
      c.checksum = payload_checksum(intended_.data(), n);
      const int attack = static_cast<int>(rng_() % 14);
      ++attacks[attack];
      switch (attack) {
        case 0:
        case 1:
        case 2:
          break;  // correct (the scribbler may still spoil it)
        case 3:
          for (auto* p = reinterpret_cast<uint8_t*>(&c); p < reinterpret_cast<uint8_t*>(&c + 1); ++p)
            *p = static_cast<uint8_t>(rng_());
          break;
        case 4:
          c.slot = slots + static_cast<uint32_t>(rng_() % 1000);
          break;
        case 5:
          c.slot = kNoSlot;
          break;
        case 6:
          c.byte_size = seg_->slot_bytes() + 1 + rng_() % 4096;
          break;
        case 7:
          c.byte_size = ~0ull - rng_() % 16;
          break;
        case 8:
          c.width += 1;
          c.byte_size = bytes;
          break;
        case 9:
          c.format ^= 1u;
          break;
        case 10:
          c.generation += 1 + rng_() % 5;
          break;
        case 11:
          c.texture_id = static_cast<uint32_t>(rng_());
          break;
        case 12:
          c.status = 1000 + static_cast<uint32_t>(rng_() % 100);
          break;
        case 13:
          std::this_thread::sleep_for(std::chrono::milliseconds(rng_() % 150));
          break;  // a stall
      }
      (void)completions_.try_push(c);
      if (rng_() % 8 == 0) (void)completions_.try_push(c);  // a duplicate
    }
  }
  Segment& segment() { return *seg_; }
  uint64_t attacks[14] = {};

 private:
  std::mt19937_64 rng_;
  std::vector<std::byte> intended_;  // the payload as meant, reused between answers
  std::unique_ptr<Segment> seg_;
  SpscRingConsumer<RequestRecord> requests_;
  SpscRingProducer<CompletionRecord> completions_;
};

// Flips bytes in the staging slots and in the completion records while the client reads them.
void scribble(Segment& seg, const std::atomic<bool>& stop, uint64_t seed, uint64_t& flips) {
  std::mt19937_64 rng(seed);
  const uint32_t slots = seg.slot_count();
  auto* records = reinterpret_cast<volatile uint8_t*>(seg.completion_records());
  const uint64_t record_bytes = uint64_t{seg.header().completion_capacity} * sizeof(CompletionRecord);
  while (!stop.load()) {
    if (rng() % 2) {
      std::span<std::byte> s = seg.slot(static_cast<uint32_t>(rng() % slots));
      auto* p = reinterpret_cast<volatile uint8_t*>(s.data());
      const uint64_t i = rng() % 4096;  // the small mips live at the start
      p[i] = static_cast<uint8_t>(p[i] ^ (1u << (rng() % 8)));
    } else {
      const uint64_t i = rng() % record_bytes;
      records[i] = static_cast<uint8_t>(records[i] ^ (1u << (rng() % 8)));
    }
    ++flips;
    if (flips % 64 == 0) std::this_thread::sleep_for(50us);
  }
}

TEST(ChaosHostileServer, EveryLieIsRefusedAndOnlyExactPayloadsAreCommitted) {
  const std::string name = chaos_test::unique("hostile");
  stream::StreamClientOptions external;
  external.spawn_server = false;
  external.request_timeout = 200ms;  // garbled answers leave requests in flight: free them quickly
  auto started = stream::StreamClient::start(config(name), shapes(), "/nonexistent-scene", "", {}, external);
  ASSERT_TRUE(started.ok()) << started.error().message;
  auto client = std::move(*started);
  HostileServer hostile(name, 42);
  std::atomic<bool> stop{false};
  uint64_t flips = 0;
  std::thread server([&] { hostile.run(stop); });
  std::thread scribbler([&] { scribble(hostile.segment(), stop, 7, flips); });

  VerifyingSink sink;
  std::mt19937_64 rng(1);
  // At least 3 s, and on a busy machine until each kind of damage below has been seen (or a hang).
  const auto start = Clock::now();
  const auto seen_enough = [&] {
    const stream::StreamStats s = client->stats();
    return sink.good_commits > 0 && s.protocol_errors > 100 && s.requests_timed_out > 0 &&
           s.payload_checksum_failures > 0;
  };
  Clock::duration longest_poll{0};
  while (Clock::now() - start < 3s || (!seen_enough() && Clock::now() - start < test::kHangAfter)) {
    client->begin_cycle();
    for (int i = 0; i < 8; ++i) {
      const auto t = static_cast<uint32_t>(rng() % 3);
      (void)client->try_request(TextureId(t), MipLevel(static_cast<uint32_t>(rng() % shapes()[t].mip_count)), 1.0f);
    }
    const auto t0 = Clock::now();
    client->poll(sink, 16);
    longest_poll = std::max(longest_poll, Clock::now() - t0);
    std::this_thread::sleep_for(200us);
  }
  stop = true;
  server.join();
  scribbler.join();

  const stream::StreamStats st = client->stats();
  std::printf(
      "hostile: %llu good commits, %llu rejects, %llu failures, %llu protocol errors, %llu checksum "
      "failures, %llu scribbles, longest poll %.3f ms, IPC p99.99 %.1f us\n",
      static_cast<unsigned long long>(sink.good_commits), static_cast<unsigned long long>(sink.rejects),
      static_cast<unsigned long long>(sink.failures), static_cast<unsigned long long>(st.protocol_errors),
      static_cast<unsigned long long>(st.payload_checksum_failures), static_cast<unsigned long long>(flips),
      std::chrono::duration<double, std::milli>(longest_poll).count(), client->ipc_time().quantile_us(0.9999));
  EXPECT_EQ(sink.bad_commits, 0u) << "a payload that is not exactly the mip was committed";
  EXPECT_GT(sink.good_commits, 0u) << "correct answers must still get through";
  EXPECT_GT(st.protocol_errors, 100u);
  EXPECT_GT(st.requests_timed_out, 0u) << "answers the hostile server garbled must time out";
  EXPECT_GT(st.payload_checksum_failures, 0u) << "the scribbler should have spoilt some payloads";
  EXPECT_LE(st.slots_held, uint64_t{hostile.segment().slot_count()});
  EXPECT_LT(longest_poll, test::promptly(50ms)) << "a poll must never wait on the server";

  // Once the peer is replaced (reset: rings and server block as new), a well-behaved answer is accepted.
  client->reset_external_server(sink);
  EXPECT_EQ(client->stats().in_flight, 0u);
  EXPECT_EQ(client->stats().slots_held, 0u);
  auto seg = Segment::open(name);
  ASSERT_TRUE(seg.ok());
  SpscRingConsumer<RequestRecord> req = (*seg)->request_consumer();
  SpscRingProducer<CompletionRecord> comp = (*seg)->completion_producer();
  client->begin_cycle();
  ASSERT_EQ(client->try_request(TextureId(0), MipLevel(4), 1.0f), stream::RequestOutcome::kSent);
  auto r = req.try_pop();
  ASSERT_TRUE(r.has_value());
  const Extent2D e = mip_extent(64, 64, 4);
  const uint64_t bytes = mip_bytes(TexelFormat::kRgba8, e);
  std::span<std::byte> dst = (*seg)->slot(0);
  for (uint64_t i = 0; i < bytes; ++i) dst[i] = pattern(0, 4, i);
  CompletionRecord c{};
  c.status = static_cast<uint32_t>(CompletionStatus::kOk);
  c.request_kind = static_cast<uint32_t>(RequestKind::kLoad);
  c.slot = 0;
  c.texture_id = 0;
  c.mip_level = 4;
  c.generation = r->generation;
  c.byte_size = bytes;
  c.format = static_cast<uint32_t>(TexelFormat::kRgba8);
  c.width = e.width;
  c.height = e.height;
  c.checksum = payload_checksum(dst.data(), bytes);
  ASSERT_TRUE(comp.try_push(c));
  const uint64_t before = sink.good_commits;
  client->poll(sink, 4);
  EXPECT_EQ(sink.good_commits, before + 1);
  EXPECT_EQ(sink.bad_commits, 0u);
}

}  // namespace
}  // namespace texstream
