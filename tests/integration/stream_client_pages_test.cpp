// StreamClient's page requests (RequestKind::kLoadPage, issue 28) against a fake server in a thread on a real
// shared segment: good pages reach the PageSink byte for byte and their slots go back; records wrong in one
// field (byte size, format, side, checksum, a page never asked for) are refused before a slot byte is used,
// with page_failed and the slot handed back; the server's failure statuses, requests lost with a reset
// server and requests past the timeout end in page_failed; requests for pages the client's own page file
// does not have never leave it.
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <functional>
#include <map>
#include <mutex>
#include <thread>
#include <vector>

#include "../support/memory_page_file.hpp"
#include "../support/patience.hpp"
#include "../support/unique_name.hpp"
#include "texstream/protocol/checksum.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/stream/stream_client.hpp"

namespace texstream {
namespace {

using namespace std::chrono_literals;
using test::MemoryPageFile;
using test::unique_name;

Config small_config(const std::string& segment) {
  Config c;
  c.protocol.segment_name = segment;
  c.protocol.request_ring_capacity = 64;
  c.protocol.completion_ring_capacity = 64;
  c.protocol.staging_slot_count = 4;
  c.protocol.staging_slot_bytes = 64 << 10;
  c.cache.layer_extent_px = 64;
  c.stream.max_requests_in_flight = 32;
  return c;
}

// Plays texstream-server in its own thread: answers each kLoadPage with the page's bytes in a free slot, then
// `spoil` may change the record (or, returning false, answer nothing); takes releases back and counts any of a
// slot it owns.
class FakePageServer {
 public:
  using Spoil = std::function<bool(CompletionRecord&, std::span<std::byte> slot)>;
  FakePageServer(const std::string& name, const MemoryPageFile& pages, Spoil spoil)
      : pages_(pages), spoil_(std::move(spoil)) {
    auto seg = Segment::open(name);
    EXPECT_TRUE(seg.ok()) << (seg.ok() ? "" : seg.error().message);
    seg_ = std::move(*seg);
    requests_ = seg_->request_consumer();
    completions_ = seg_->completion_producer();
    owned_.assign(seg_->slot_count(), true);
    seg_->server_block().pid.v.store(static_cast<uint32_t>(::getpid()));
    seg_->server_block().attached.v.store(1);
    thread_ = std::thread([this] { run(); });
  }
  ~FakePageServer() {
    stop_ = true;
    thread_.join();
  }
  int releases() const { return releases_.load(); }
  int bad_releases() const { return bad_releases_.load(); }
  int owned() const {
    std::lock_guard lock(mutex_);
    return static_cast<int>(std::count(owned_.begin(), owned_.end(), true));
  }

 private:
  void run() {
    while (!stop_) {
      seg_->server_block().heartbeat.v.fetch_add(1);
      while (auto r = requests_.try_pop()) {
        std::lock_guard lock(mutex_);
        if (r->kind == static_cast<uint32_t>(RequestKind::kReleaseSlot)) {
          if (r->slot >= owned_.size() || owned_[r->slot]) {
            ++bad_releases_;
          } else {
            owned_[r->slot] = true;
            ++releases_;
          }
        } else if (r->kind == static_cast<uint32_t>(RequestKind::kLoadPage)) {
          answer(*r);
        }
      }
      std::this_thread::sleep_for(200us);
    }
  }
  void answer(const RequestRecord& r) {
    const auto slot = static_cast<uint32_t>(std::find(owned_.begin(), owned_.end(), true) - owned_.begin());
    ASSERT_LT(slot, owned_.size()) << "fake server out of slots";
    const pages::PageId p{r.mip_level, r.page_x, r.page_y};
    const std::span<const std::byte> page = pages_.page(p);
    std::span<std::byte> dst = seg_->slot(slot);
    std::memcpy(dst.data(), page.data(), page.size());
    CompletionRecord c{};
    c.status = static_cast<uint32_t>(CompletionStatus::kOk);
    c.request_kind = static_cast<uint32_t>(RequestKind::kLoadPage);
    c.slot = slot;
    c.texture_id = r.texture_id;
    c.mip_level = r.mip_level;
    c.page_x = r.page_x;
    c.page_y = r.page_y;
    c.generation = r.generation;
    c.byte_size = page.size();
    c.format = static_cast<uint32_t>(TexelFormat::kRgba8);
    c.width = 8;
    c.height = 8;
    c.checksum = payload_checksum(dst.data(), page.size());
    if (!spoil_(c, dst)) return;
    if (c.status == static_cast<uint32_t>(CompletionStatus::kOk) && c.slot < owned_.size()) owned_[c.slot] = false;
    EXPECT_TRUE(completions_.try_push(c));
  }

  const MemoryPageFile& pages_;
  Spoil spoil_;
  std::unique_ptr<Segment> seg_;
  SpscRingConsumer<RequestRecord> requests_;
  SpscRingProducer<CompletionRecord> completions_;
  mutable std::mutex mutex_;
  std::vector<bool> owned_;
  std::atomic<int> releases_{0}, bad_releases_{0};
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

struct PageEvent {
  enum Kind { kCommit, kFailed } kind;
  uint32_t file;
  pages::PageId page;
  CompletionStatus status = CompletionStatus::kOk;
  std::vector<std::byte> data;
};

class RecordingPageSink : public stream::PageSink {
 public:
  std::span<std::byte> reserve_page(uint32_t, pages::PageId, uint64_t bytes) override {
    if (no_room > 0) {
      --no_room;
      return {};
    }
    buffer.assign(bytes + 32, std::byte{0});  // larger than asked: the client uses only the first `bytes`
    return buffer;
  }
  void commit_page(uint32_t file, pages::PageId page, std::span<std::byte> data) override {
    EXPECT_EQ(data.data(), buffer.data()) << "commit must hand back our memory";
    events.push_back({PageEvent::kCommit, file, page, CompletionStatus::kOk, {data.begin(), data.end()}});
  }
  void page_failed(uint32_t file, pages::PageId page, CompletionStatus status) override {
    events.push_back({PageEvent::kFailed, file, page, status, {}});
  }
  int no_room = 0;
  std::vector<std::byte> buffer;
  std::vector<PageEvent> events;
};

// Mips never asked for in these tests: any call is a failure.
class NoMips : public stream::MipSink {
 public:
  std::span<std::byte> reserve(TextureId, MipLevel, uint64_t) override {
    ADD_FAILURE() << "a mip reserve";
    return {};
  }
  void commit(TextureId, MipLevel, std::span<std::byte>) override { ADD_FAILURE() << "a mip commit"; }
  void reject(TextureId, MipLevel, std::span<std::byte>) override { ADD_FAILURE() << "a mip reject"; }
  void failed(TextureId, MipLevel, CompletionStatus) override { ADD_FAILURE() << "a mip failure"; }
};

class StreamClientPages : public ::testing::Test {
 protected:
  void start(stream::StreamClientOptions o = {}) {
    ASSERT_NE(pages_.file, nullptr);  // a two-level file: the root and its 4 children
    config_ = small_config(unique_name("pages"));
    o.spawn_server = false;
    auto c = stream::StreamClient::start(config_, {{16, 16, 5, TexelFormat::kRgba8}}, "/nonexistent-scene", "", {}, o);
    ASSERT_TRUE(c.ok()) << c.error().message;
    client_ = std::move(*c);
    client_->set_page_files({pages_.file}, &sink_);
  }
  void serve(FakePageServer::Spoil spoil) {
    server_ = std::make_unique<FakePageServer>(config_.protocol.segment_name, pages_, std::move(spoil));
  }
  // Polls until the sink has `n` events (or a hang).
  void poll_until(size_t n) {
    const auto end = std::chrono::steady_clock::now() + test::kHangAfter;
    while (sink_.events.size() < n && std::chrono::steady_clock::now() < end) {
      client_->poll(mips_, 16);
      std::this_thread::sleep_for(200us);
    }
    ASSERT_EQ(sink_.events.size(), n);
  }
  // Polls until the fake server has `n` slot releases back (the client flushes them at its next call).
  void poll_until_released(int n) {
    const auto end = std::chrono::steady_clock::now() + test::kHangAfter;
    while (server_->releases() < n && std::chrono::steady_clock::now() < end) {
      client_->poll(mips_, 16);
      std::this_thread::sleep_for(200us);
    }
    EXPECT_EQ(server_->releases(), n);
    EXPECT_EQ(server_->bad_releases(), 0);
  }
  // One page asked, answered by a record `spoil` makes wrong in one field: refused, failed, slot back.
  void expect_refused(FakePageServer::Spoil spoil, const char* what) {
    SCOPED_TRACE(what);
    start();
    serve(std::move(spoil));
    client_->begin_cycle();
    ASSERT_EQ(client_->try_request_page(0, {1, 1, 0}, 1.0f), stream::RequestOutcome::kSent);
    poll_until(1);
    EXPECT_EQ(sink_.events[0].kind, PageEvent::kFailed);
    EXPECT_EQ(sink_.events[0].status, CompletionStatus::kIoError);
    EXPECT_EQ(sink_.events[0].page, (pages::PageId{1, 1, 0}));
    EXPECT_FALSE(client_->page_in_flight(0, {1, 1, 0}));
    EXPECT_GE(client_->stats().protocol_errors, 1u);
    EXPECT_EQ(client_->stats().pages_failed, 1u);
    EXPECT_EQ(client_->stats().pages_ok, 0u);
    poll_until_released(1);  // the slot it claimed to hand over goes back, once
    EXPECT_EQ(client_->stats().slots_held, 0u);
  }

  MemoryPageFile pages_;
  Config config_;
  std::unique_ptr<stream::StreamClient> client_;
  std::unique_ptr<FakePageServer> server_;
  RecordingPageSink sink_;
  NoMips mips_;
};

TEST_F(StreamClientPages, PagesReachTheSinkExactlyAndTheirSlotsGoBack) {
  start();
  serve([](CompletionRecord&, std::span<std::byte>) { return true; });
  client_->begin_cycle();
  sink_.no_room = 1;  // the first is held once, then delivered in order
  const std::vector<pages::PageId> asked = {{0, 0, 0}, {1, 0, 0}, {1, 1, 1}};
  for (const pages::PageId& p : asked) ASSERT_EQ(client_->try_request_page(0, p, 1.0f), stream::RequestOutcome::kSent);
  EXPECT_TRUE(client_->page_in_flight(0, {1, 1, 1}));
  EXPECT_EQ(client_->try_request_page(0, {1, 1, 1}, 1.0f), stream::RequestOutcome::kAlreadyInFlight);
  poll_until(asked.size());
  for (size_t i = 0; i < asked.size(); ++i) {
    const PageEvent& e = sink_.events[i];
    EXPECT_EQ(e.kind, PageEvent::kCommit);
    EXPECT_EQ(e.page, asked[i]);
    const std::span<const std::byte> want = pages_.page(asked[i]);
    EXPECT_TRUE(std::equal(e.data.begin(), e.data.end(), want.begin(), want.end())) << i;
  }
  poll_until_released(static_cast<int>(asked.size()));
  const stream::StreamStats s = client_->stats();
  EXPECT_EQ(s.pages_requested, 3u);
  EXPECT_EQ(s.pages_ok, 3u);
  EXPECT_EQ(s.pages_failed, 0u);
  EXPECT_EQ(s.protocol_errors, 0u);
  EXPECT_EQ(s.in_flight, 0u);
  const std::string text = client_->stats_text();
  EXPECT_NE(text.find("pages_requested 3"), std::string::npos) << text;
  EXPECT_NE(text.find("pages_ok 3"), std::string::npos) << text;
}

TEST_F(StreamClientPages, APageHeldForRoomIsDroppedWhenItsFileIsUnregistered) {
  start();
  serve([](CompletionRecord&, std::span<std::byte>) { return true; });
  client_->begin_cycle();
  sink_.no_room = 1000;
  ASSERT_EQ(client_->try_request_page(0, {0, 0, 0}, 1.0f), stream::RequestOutcome::kSent);
  const auto end = std::chrono::steady_clock::now() + test::kHangAfter;
  while (client_->stats().slots_held == 0 && std::chrono::steady_clock::now() < end) {
    client_->poll(mips_, 16);  // answered, held: no room
    std::this_thread::sleep_for(200us);
  }
  ASSERT_EQ(client_->stats().slots_held, 1u);
  client_->set_page_files({}, nullptr);
  poll_until_released(1);
  EXPECT_TRUE(sink_.events.empty());
  EXPECT_EQ(client_->stats().pages_failed, 1u);
  EXPECT_FALSE(client_->page_in_flight(0, {0, 0, 0}));
}

TEST_F(StreamClientPages, RequestsForPagesTheFileDoesNotHaveNeverLeave) {
  start();
  client_->begin_cycle();
  EXPECT_EQ(client_->try_request_page(1, {0, 0, 0}, 1.0f), stream::RequestOutcome::kUnknownPageFile);
  EXPECT_EQ(client_->try_request_page(0, {2, 0, 0}, 1.0f), stream::RequestOutcome::kPageNotStored);
  EXPECT_EQ(client_->try_request_page(0, {1, 2, 0}, 1.0f), stream::RequestOutcome::kPageNotStored);
  EXPECT_EQ(client_->try_request_page(0, {0xffffffffu, 0, 0}, 1.0f), stream::RequestOutcome::kPageNotStored);
  EXPECT_EQ(stream::to_send_result(stream::RequestOutcome::kPageNotStored), stream::SendResult::kSkip);
  EXPECT_EQ(client_->stats().pages_requested, 0u);
  EXPECT_EQ(client_->segment().renderer_block().doorbell.v.load(), 0u) << "nothing was pushed";
}

TEST_F(StreamClientPages, WrongByteSizeIsRefused) {
  expect_refused(
      [](CompletionRecord& c, std::span<std::byte> slot) {
        c.byte_size -= 4;  // fits the slot, checksum of those bytes: only the index entry tells
        c.checksum = payload_checksum(slot.data(), c.byte_size);
        return true;
      },
      "byte_size");
}

TEST_F(StreamClientPages, WrongFormatIsRefused) {
  expect_refused(
      [](CompletionRecord& c, std::span<std::byte>) {
        c.format = static_cast<uint32_t>(TexelFormat::kBc1);
        return true;
      },
      "format");
}

TEST_F(StreamClientPages, WrongSideIsRefused) {
  expect_refused(
      [](CompletionRecord& c, std::span<std::byte>) {
        c.width = 16;
        return true;
      },
      "width");
}

TEST_F(StreamClientPages, WrongChecksumIsRefused) {
  expect_refused(
      [](CompletionRecord& c, std::span<std::byte>) {
        c.checksum ^= 1;
        return true;
      },
      "checksum");
  EXPECT_EQ(client_->stats().payload_checksum_failures, 1u);
}

TEST_F(StreamClientPages, AnAnswerForAnotherPageIsRefused) {
  start();
  serve([](CompletionRecord& c, std::span<std::byte>) {
    c.page_x = 0;  // asked (1,1,0), answered (1,0,0): stored, never asked
    return true;
  });
  client_->begin_cycle();
  ASSERT_EQ(client_->try_request_page(0, {1, 1, 0}, 1.0f), stream::RequestOutcome::kSent);
  const auto end = std::chrono::steady_clock::now() + test::kHangAfter;
  while (client_->stats().protocol_errors == 0 && std::chrono::steady_clock::now() < end) {
    client_->poll(mips_, 16);
    std::this_thread::sleep_for(200us);
  }
  EXPECT_EQ(client_->stats().protocol_errors, 1u);
  EXPECT_TRUE(sink_.events.empty()) << "nothing asked was answered";
  EXPECT_TRUE(client_->page_in_flight(0, {1, 1, 0}));
  poll_until_released(1);
}

TEST_F(StreamClientPages, AnUnknownRequestKindIsRefused) {
  expect_refused(
      [](CompletionRecord& c, std::span<std::byte>) {
        c.request_kind = 7;
        return true;
      },
      "request_kind");
}

TEST_F(StreamClientPages, TheServersStatusEndsTheRequest) {
  start();
  serve([](CompletionRecord& c, std::span<std::byte>) {
    c.status = static_cast<uint32_t>(CompletionStatus::kNotFound);
    c.slot = kNoSlot;
    c.byte_size = 0;
    return true;
  });
  client_->begin_cycle();
  ASSERT_EQ(client_->try_request_page(0, {0, 0, 0}, 1.0f), stream::RequestOutcome::kSent);
  poll_until(1);
  EXPECT_EQ(sink_.events[0].kind, PageEvent::kFailed);
  EXPECT_EQ(sink_.events[0].status, CompletionStatus::kNotFound);
  EXPECT_EQ(client_->stats().protocol_errors, 0u);
  EXPECT_EQ(client_->stats().pages_failed, 1u);
}

TEST_F(StreamClientPages, RequestsLostWithAResetServerFailCancelled) {
  start();
  client_->begin_cycle();
  ASSERT_EQ(client_->try_request_page(0, {1, 0, 1}, 1.0f), stream::RequestOutcome::kSent);
  client_->reset_external_server(mips_);  // no server attached: nothing answers, everything in flight is lost
  ASSERT_EQ(sink_.events.size(), 1u);
  EXPECT_EQ(sink_.events[0].kind, PageEvent::kFailed);
  EXPECT_EQ(sink_.events[0].status, CompletionStatus::kCancelled);
  EXPECT_FALSE(client_->page_in_flight(0, {1, 0, 1}));
  EXPECT_EQ(client_->stats().requests_lost, 1u);
}

TEST_F(StreamClientPages, UnansweredRequestsTimeOut) {
  auto now = std::chrono::steady_clock::now();
  stream::StreamClientOptions o;
  o.clock = [&now] { return now; };
  o.request_timeout = 100ms;
  start(o);
  client_->begin_cycle();
  ASSERT_EQ(client_->try_request_page(0, {0, 0, 0}, 1.0f), stream::RequestOutcome::kSent);
  client_->poll(mips_, 16);
  EXPECT_TRUE(sink_.events.empty());
  now += 101ms;
  client_->poll(mips_, 16);
  ASSERT_EQ(sink_.events.size(), 1u);
  EXPECT_EQ(sink_.events[0].status, CompletionStatus::kTimedOut);
  EXPECT_EQ(client_->stats().requests_timed_out, 1u);
}

}  // namespace
}  // namespace texstream
