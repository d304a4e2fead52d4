// StreamClient against a fake server on a real shared segment. The fake opens the segment with
// Segment::open and plays texstream-server's side of the protocol: it answers loads with correct payloads,
// or with records that are wrong in one field each, and checks that the client never hands back a slot the
// server already owns. Most tests drive the fake step by step from the test thread (deterministic); one
// runs it in its own thread against the client's frame loop. The restart tests let the client spawn a
// stand-in process (a shell script that only sleeps) so that death, hang and restart are real.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <thread>
#include <vector>

#include "../support/forked_child.hpp"
#include "../support/patience.hpp"
#include "../support/unique_name.hpp"
#include "texstream/protocol/checksum.hpp"
#include "texstream/protocol/liveness.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/stream/stream_client.hpp"

namespace texstream {
namespace {

using test::unique_name;

using namespace std::chrono_literals;

// ---- the texture table the tests stream from ----
// 0: 64x64 RGBA8 (7 mips; level 4 = 4x4 = 64 B, level 0 = 16 KiB), 1: 128x32 RGBA8, 2: 256x256 BC1 (9 mips).
std::vector<TextureShape> shapes() {
  return {{64, 64, 7, TexelFormat::kRgba8}, {128, 32, 8, TexelFormat::kRgba8}, {256, 256, 9, TexelFormat::kBc1}};
}

uint64_t shape_bytes(const TextureShape& s, uint32_t mip) { return mip_bytes(s.format, s.width, s.height, mip); }

std::byte pattern(uint32_t texture, uint32_t mip, uint64_t i) {
  return static_cast<std::byte>((texture * 31u + mip * 7u + i * 13u + (i >> 8)) & 0xffu);
}

Config small_config(const std::string& segment) {
  Config c;
  c.protocol.segment_name = segment;
  c.protocol.request_ring_capacity = 64;
  c.protocol.completion_ring_capacity = 64;
  c.protocol.staging_slot_count = 4;
  c.protocol.staging_slot_bytes = 64 << 10;
  c.cache.layer_extent_px = 64;  // validate(): the largest cached mip must fit a staging slot
  c.stream.max_requests_in_flight = 32;
  return c;
}

// ---- the fake server ----
class FakeServer {
 public:
  explicit FakeServer(const std::string& name) {
    auto seg = Segment::open(name);
    EXPECT_TRUE(seg.ok()) << (seg.ok() ? "" : seg.error().message);
    seg_ = std::move(*seg);
    attach();
  }

  // After the client reset the segment (a "restart"): fresh ring endpoints, every slot ours again.
  void attach() {
    requests_ = seg_->request_consumer();
    completions_ = seg_->completion_producer();
    owned_.assign(seg_->slot_count(), true);
    ServerBlock& sb = seg_->server_block();
    sb.pid.v.store(static_cast<uint32_t>(::getpid()));
    sb.attached.v.store(1);
  }

  Segment& segment() { return *seg_; }
  void beat() { seg_->server_block().heartbeat.v.fetch_add(1); }

  // Takes every request off the ring: loads are returned, releases hand slots back (and are checked).
  std::vector<RequestRecord> drain() {
    std::vector<RequestRecord> loads;
    while (auto r = requests_.try_pop()) {
      if (r->kind == static_cast<uint32_t>(RequestKind::kLoad)) {
        loads.push_back(*r);
      } else if (r->kind == static_cast<uint32_t>(RequestKind::kReleaseSlot)) {
        if (r->slot >= owned_.size() || owned_[r->slot]) {
          ++bad_releases;  // released a slot it does not own
        } else {
          owned_[r->slot] = true;
          ++releases;
          ++released_per_slot[r->slot];
        }
      } else {
        ++bad_kinds;
      }
    }
    return loads;
  }

  int free_slot() const {
    for (size_t i = 0; i < owned_.size(); ++i)
      if (owned_[i]) return static_cast<int>(i);
    return -1;
  }
  size_t owned_count() const { return static_cast<size_t>(std::count(owned_.begin(), owned_.end(), true)); }

  // A correct kOk answer in a free slot; `edit` may then spoil one field. Returns the record pushed.
  template <class Edit>
  CompletionRecord answer(const RequestRecord& load, const TextureShape& shape, Edit edit) {
    const int slot = free_slot();
    EXPECT_GE(slot, 0) << "fake server out of slots";
    const Extent2D e = mip_extent(shape.width, shape.height, load.mip_level);
    const uint64_t bytes = mip_bytes(shape.format, e);
    std::span<std::byte> dst = seg_->slot(static_cast<uint32_t>(slot));
    for (uint64_t i = 0; i < bytes; ++i) dst[i] = pattern(load.texture_id, load.mip_level, i);
    CompletionRecord c{};
    c.status = static_cast<uint32_t>(CompletionStatus::kOk);
    c.request_kind = static_cast<uint32_t>(RequestKind::kLoad);
    c.slot = static_cast<uint32_t>(slot);
    c.texture_id = load.texture_id;
    c.mip_level = load.mip_level;
    c.generation = load.generation;
    c.byte_size = bytes;
    c.format = static_cast<uint32_t>(shape.format);
    c.width = e.width;
    c.height = e.height;
    c.checksum = payload_checksum(dst.data(), bytes);
    edit(c);
    // The slot is handed over only if the record claims kOk with an in-range slot.
    if (c.status == static_cast<uint32_t>(CompletionStatus::kOk) && c.slot < owned_.size()) owned_[c.slot] = false;
    EXPECT_TRUE(completions_.try_push(c));
    return c;
  }
  CompletionRecord answer(const RequestRecord& load, const TextureShape& shape) {
    return answer(load, shape, [](CompletionRecord&) {});
  }

  void fail(const RequestRecord& load, CompletionStatus status) {
    CompletionRecord c{};
    c.status = static_cast<uint32_t>(status);
    c.request_kind = static_cast<uint32_t>(RequestKind::kLoad);
    c.slot = kNoSlot;
    c.texture_id = load.texture_id;
    c.mip_level = load.mip_level;
    c.generation = load.generation;
    EXPECT_TRUE(completions_.try_push(c));
  }

  void push_raw(const CompletionRecord& c) { EXPECT_TRUE(completions_.try_push(c)); }
  void set_owned(uint32_t slot, bool owned) { owned_[slot] = owned; }

  int bad_releases = 0;
  int bad_kinds = 0;
  int releases = 0;
  std::map<uint32_t, int> released_per_slot;

 private:
  std::unique_ptr<Segment> seg_;
  SpscRingConsumer<RequestRecord> requests_;
  SpscRingProducer<CompletionRecord> completions_;
  std::vector<bool> owned_;
};

// ---- a sink that records everything ----
struct Event {
  enum Kind { kCommit, kReject, kFailed } kind;
  uint32_t texture;
  uint32_t mip;
  CompletionStatus status = CompletionStatus::kOk;
  bool reserved = false;  // reject: a reserved span was handed back
};

class RecordingSink : public stream::MipSink {
 public:
  std::span<std::byte> reserve(TextureId t, MipLevel m, uint64_t bytes) override {
    ++reserves;
    if (no_room > 0) {
      --no_room;
      return {};
    }
    buffers.emplace_back(bytes + 64);  // larger than asked: the client must only use the first `bytes`
    last_reserved = {buffers.back().data(), buffers.back().size()};
    reserved_for[{t.value, m.value}] = last_reserved;
    return last_reserved;
  }
  void commit(TextureId t, MipLevel m, std::span<std::byte> data) override {
    events.push_back({Event::kCommit, t.value, m.value});
    const auto it = reserved_for.find({t.value, m.value});
    EXPECT_NE(it, reserved_for.end()) << "commit without reserve";
    if (it != reserved_for.end()) {
      EXPECT_EQ(data.data(), it->second.data()) << "commit must hand back our memory";
    }
    committed[{t.value, m.value}].assign(data.begin(), data.end());
  }
  void reject(TextureId t, MipLevel m, std::span<std::byte> reserved) override {
    events.push_back({Event::kReject, t.value, m.value, CompletionStatus::kOk, !reserved.empty()});
  }
  void failed(TextureId t, MipLevel m, CompletionStatus s) override {
    events.push_back({Event::kFailed, t.value, m.value, s});
  }

  size_t count(Event::Kind k) const {
    return static_cast<size_t>(
        std::count_if(events.begin(), events.end(), [k](const Event& e) { return e.kind == k; }));
  }
  bool payload_ok(uint32_t t, uint32_t m) const {
    const auto it = committed.find({t, m});
    if (it == committed.end()) return false;
    for (uint64_t i = 0; i < it->second.size(); ++i)
      if (it->second[i] != pattern(t, m, i)) return false;
    return it->second.size() == shape_bytes(shapes()[t], m);
  }

  int no_room = 0;
  int reserves = 0;
  std::vector<Event> events;
  std::vector<std::vector<std::byte>> buffers;
  std::span<std::byte> last_reserved;
  std::map<std::pair<uint32_t, uint32_t>, std::span<std::byte>> reserved_for;
  std::map<std::pair<uint32_t, uint32_t>, std::vector<std::byte>> committed;
};

stream::StreamClientOptions external() {
  stream::StreamClientOptions o;
  o.spawn_server = false;
  return o;
}

std::unique_ptr<stream::StreamClient> start_external(const Config& config) {
  auto c = stream::StreamClient::start(config, shapes(), "/nonexistent-scene", "", {}, external());
  EXPECT_TRUE(c.ok()) << (c.ok() ? "" : c.error().message);
  return c.ok() ? std::move(*c) : nullptr;
}

// A chosen protocol.segment_name (not a "texstream-" one, which the start-up sweep covers) left behind by a
// SIGKILLed renderer: the next renderer takes the name over. Before, it failed with "File exists" until
// someone removed /dev/shm/<name> by hand.
TEST(StreamClient, TakesOverAChosenSegmentNameLeftByAKilledRenderer) {
  const std::string name = "ts-test-chosen-" + std::to_string(::getpid());
  const pid_t child = test::fork_sleeper([&] {
    auto seg = Segment::create(name, {16, 16, 2, 4096});
    if (!seg.ok()) return false;
    (void)seg.value().release();  // its destructor would remove the name
    return true;
  });
  ASSERT_GT(child, 0);
  kill(child, SIGKILL);
  waitpid(child, nullptr, 0);
  auto client = start_external(small_config(name));
  ASSERT_NE(client, nullptr);
  EXPECT_EQ(client->segment().header().slot_count, 4u) << "the new renderer's own segment, not the dead one's";
}

// ---- the happy path, step by step ----

// Requests that expire unanswered are a protocol error only if a server was attached to answer them. With
// none (server.spawn = false and no standalone server yet) they fail as timed out, and no protocol error is
// counted: before, a renderer waiting for its standalone server reported "texstream-server broke the
// protocol" once per expiry, of a server that did not exist.
TEST(StreamClient, RequestsUnansweredWithNoServerAttachedAreNoProtocolError) {
  const Config config = small_config(unique_name("noserver"));
  stream::StreamClientOptions o = external();
  o.request_timeout = std::chrono::milliseconds(50);
  auto started = stream::StreamClient::start(config, shapes(), "/nonexistent-scene", "", {}, o);
  ASSERT_TRUE(started.ok()) << started.error().message;
  stream::StreamClient& client = **started;
  RecordingSink sink;
  // Polls until `n` requests have timed out (or a hang).
  const auto poll_until_timed_out = [&](uint64_t n) {
    const auto end = std::chrono::steady_clock::now() + test::kHangAfter;
    while (client.stats().requests_timed_out < n && std::chrono::steady_clock::now() < end) {
      client.poll(sink, 16);
      std::this_thread::sleep_for(5ms);
    }
  };
  client.begin_cycle();
  ASSERT_TRUE(client.request(TextureId(0), MipLevel(4), 1.0f));
  poll_until_timed_out(1);
  EXPECT_EQ(client.stats().requests_timed_out, 1u);
  EXPECT_EQ(client.stats().protocol_errors, 0u);
  ASSERT_FALSE(sink.events.empty());
  EXPECT_EQ(sink.events.back().kind, Event::kFailed);
  EXPECT_NE(client.unattached_reason().find("texstream-server --segment " + config.protocol.segment_name),
            std::string::npos)
      << client.unattached_reason();

  // A server that is attached and does not answer: that is a protocol error.
  FakeServer server(config.protocol.segment_name);
  EXPECT_EQ(client.unattached_reason(), "");
  ASSERT_TRUE(client.request(TextureId(2), MipLevel(6), 1.0f));
  poll_until_timed_out(2);
  EXPECT_EQ(client.stats().requests_timed_out, 2u);
  EXPECT_EQ(client.stats().protocol_errors, 1u);
}

TEST(StreamClient, StreamsMipsAndHandsEverySlotBack) {
  const Config config = small_config(unique_name("happy"));
  auto client = start_external(config);
  ASSERT_TRUE(client);
  FakeServer server(config.protocol.segment_name);
  RecordingSink sink;

  client->begin_cycle();
  EXPECT_EQ(client->segment().renderer_block().generation.v.load(), 1u);
  ASSERT_TRUE(client->request(TextureId(0), MipLevel(4), 5.0f));
  ASSERT_TRUE(client->request(TextureId(2), MipLevel(6), 3.0f));
  EXPECT_EQ(client->try_request(TextureId(0), MipLevel(4), 5.0f), stream::RequestOutcome::kAlreadyInFlight);
  EXPECT_EQ(client->try_request(TextureId(9), MipLevel(0), 1.0f), stream::RequestOutcome::kUnknownTexture);
  EXPECT_EQ(client->try_request(TextureId(0), MipLevel(7), 1.0f), stream::RequestOutcome::kBadMip);
  EXPECT_GE(client->segment().renderer_block().doorbell.v.load(), 2u) << "each push rings the doorbell";

  const auto loads = server.drain();
  ASSERT_EQ(loads.size(), 2u);
  EXPECT_EQ(loads[0].texture_id, 0u);
  EXPECT_EQ(loads[0].mip_level, 4u);
  EXPECT_EQ(loads[0].generation, 1u);
  EXPECT_FLOAT_EQ(loads[0].priority, 5.0f);
  for (const auto& l : loads) server.answer(l, shapes()[l.texture_id]);
  EXPECT_EQ(server.owned_count(), 2u);

  const uint64_t hb = client->segment().renderer_block().heartbeat.v.load();
  client->poll(sink, 16);
  EXPECT_EQ(client->segment().renderer_block().heartbeat.v.load(), hb + 1);
  ASSERT_EQ(sink.count(Event::kCommit), 2u);
  EXPECT_TRUE(sink.payload_ok(0, 4));
  EXPECT_TRUE(sink.payload_ok(2, 6));
  const stream::StreamStats st = client->stats();
  EXPECT_EQ(st.completions_ok, 2u);
  EXPECT_EQ(st.bytes_received, 64u + 8u);  // 4x4 RGBA8 (64 B) + 4x4 BC1 (one 8-byte block)
  EXPECT_EQ(st.in_flight, 0u);
  EXPECT_EQ(st.protocol_errors, 0u);

  server.drain();
  EXPECT_EQ(server.owned_count(), 4u) << "both slots came back";
  EXPECT_EQ(server.bad_releases, 0);
  EXPECT_EQ(server.releases, 2);

  // Status answers reach the sink as failures, and the same mip may then be asked again.
  ASSERT_TRUE(client->request(TextureId(1), MipLevel(5), 1.0f));
  server.fail(server.drain().at(0), CompletionStatus::kUnfilled);
  client->poll(sink, 16);
  ASSERT_EQ(sink.events.back().kind, Event::kFailed);
  EXPECT_EQ(sink.events.back().status, CompletionStatus::kUnfilled);
  EXPECT_EQ(client->stats().completions_failed[static_cast<uint32_t>(CompletionStatus::kUnfilled)], 1u);
  EXPECT_TRUE(client->request(TextureId(1), MipLevel(5), 1.0f));
}

TEST(StreamClient, NoRoomInTheSinkKeepsTheCompletionAndItsSlot) {
  const Config config = small_config(unique_name("noroom"));
  auto client = start_external(config);
  ASSERT_TRUE(client);
  FakeServer server(config.protocol.segment_name);
  RecordingSink sink;
  client->begin_cycle();
  ASSERT_TRUE(client->request(TextureId(0), MipLevel(3), 1));
  ASSERT_TRUE(client->request(TextureId(0), MipLevel(2), 1));
  ASSERT_TRUE(client->request(TextureId(1), MipLevel(3), 1));
  for (const auto& l : server.drain()) server.answer(l, shapes()[l.texture_id]);

  sink.no_room = 2;
  client->poll(sink, 16);
  client->poll(sink, 16);
  EXPECT_TRUE(sink.events.empty()) << "nothing delivered while the sink is full";
  EXPECT_EQ(client->stats().slots_held, 1u) << "only the first completion was taken off the ring";
  EXPECT_TRUE(client->in_flight(TextureId(0), MipLevel(3)));
  server.drain();
  EXPECT_EQ(server.releases, 0) << "the held slot must not go back before its bytes are copied";

  // Room again, but a budget of one mip per poll: in order, one at a time.
  client->poll(sink, 1);
  ASSERT_EQ(sink.count(Event::kCommit), 1u);
  EXPECT_EQ(sink.events[0].mip, 3u);
  EXPECT_EQ(sink.events[0].texture, 0u);
  client->poll(sink, 1);
  client->poll(sink, 1);
  ASSERT_EQ(sink.count(Event::kCommit), 3u);
  EXPECT_EQ(sink.events[1].mip, 2u);
  EXPECT_EQ(sink.events[2].texture, 1u);
  for (auto [t, m] : {std::pair{0u, 3u}, {0u, 2u}, {1u, 3u}}) EXPECT_TRUE(sink.payload_ok(t, m));
  server.drain();
  EXPECT_EQ(server.owned_count(), 4u);
  EXPECT_EQ(server.bad_releases, 0);
}

TEST(StreamClient, RingLimitsAndQueuedReleases) {
  Config config = small_config(unique_name("limits"));
  config.protocol.request_ring_capacity = 4;  // 1 record kept for releases (capacity / 4)
  config.protocol.completion_ring_capacity = 4;
  config.stream.max_requests_in_flight = 4;
  auto client = start_external(config);
  ASSERT_TRUE(client);
  FakeServer server(config.protocol.segment_name);
  RecordingSink sink;
  client->begin_cycle();
  // A, B, C fill the ring but for the record kept for releases.
  EXPECT_EQ(client->try_request(TextureId(0), MipLevel(6), 1), stream::RequestOutcome::kSent);
  EXPECT_EQ(client->try_request(TextureId(0), MipLevel(5), 1), stream::RequestOutcome::kSent);
  EXPECT_EQ(client->try_request(TextureId(0), MipLevel(4), 1), stream::RequestOutcome::kSent);
  EXPECT_EQ(client->try_request(TextureId(0), MipLevel(3), 1), stream::RequestOutcome::kRingFull)
      << "the last ring record is kept for slot releases";
  EXPECT_EQ(stream::to_send_result(stream::RequestOutcome::kRingFull), stream::SendResult::kStop);

  // The server takes A, B, C and answers A: its release goes out with the next poll.
  const auto abc = server.drain();
  ASSERT_EQ(abc.size(), 3u);
  server.answer(abc[0], shapes()[0]);
  client->poll(sink, 16);
  EXPECT_EQ(client->stats().releases_sent, 1u);
  // D and E take the ring to [release A, D, E]; B and C are still in flight: the limit of 4 is reached.
  EXPECT_EQ(client->try_request(TextureId(1), MipLevel(7), 1), stream::RequestOutcome::kSent);
  EXPECT_EQ(client->try_request(TextureId(1), MipLevel(6), 1), stream::RequestOutcome::kSent);
  EXPECT_EQ(client->try_request(TextureId(1), MipLevel(5), 1), stream::RequestOutcome::kInFlightLimit);
  EXPECT_EQ(stream::to_send_result(stream::RequestOutcome::kInFlightLimit), stream::SendResult::kStop);
  // B and C complete while the server has not read the ring: one release fits, the other waits locally.
  server.answer(abc[1], shapes()[0]);
  server.answer(abc[2], shapes()[0]);
  client->poll(sink, 16);
  EXPECT_EQ(sink.count(Event::kCommit), 3u);
  stream::StreamStats st = client->stats();
  EXPECT_EQ(st.releases_sent, 2u);
  EXPECT_EQ(st.releases_queued, 1u);
  EXPECT_EQ(st.slots_held, 1u) << "a queued release still holds its slot";
  // The server reads the ring; the next poll pushes the queued release before anything else.
  EXPECT_EQ(server.drain().size(), 2u);  // D and E (the releases are counted separately)
  client->poll(sink, 16);
  st = client->stats();
  EXPECT_EQ(st.releases_queued, 0u);
  EXPECT_EQ(st.slots_held, 0u);
  server.drain();
  EXPECT_EQ(server.releases, 3);
  EXPECT_EQ(server.bad_releases, 0);
  EXPECT_EQ(server.owned_count(), 4u);
}

TEST(StreamClient, DoorbellWakesASleepingServer) {
  const Config config = small_config(unique_name("doorbell"));
  auto client = start_external(config);
  ASSERT_TRUE(client);
  FakeServer server(config.protocol.segment_name);
  std::atomic<bool> woke{false};
  std::atomic<bool> sleeping{false};
  std::thread t([&] {
    ServerBlock& sb = server.segment().server_block();
    RendererBlock& rb = server.segment().renderer_block();
    const uint32_t seen = rb.doorbell.v.load(std::memory_order_acquire);
    sb.sleeping.v.store(1, std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_seq_cst);
    sleeping = true;
    const auto t0 = std::chrono::steady_clock::now();
    // A wait of test::kHangAfter: only the wake (or the value changing before the wait) ends it in time.
    while (rb.doorbell.v.load(std::memory_order_acquire) == seen &&
           std::chrono::steady_clock::now() - t0 < test::kHangAfter) {
      futex_wait(rb.doorbell, seen, test::kHangAfter);
    }
    sb.sleeping.v.store(0, std::memory_order_relaxed);
    woke = std::chrono::steady_clock::now() - t0 < test::promptly(500ms);
  });
  while (!sleeping) std::this_thread::sleep_for(1ms);
  std::this_thread::sleep_for(20ms);  // let it enter the futex
  const auto t0 = std::chrono::steady_clock::now();
  client->begin_cycle();
  ASSERT_TRUE(client->request(TextureId(0), MipLevel(6), 1));
  t.join();
  EXPECT_TRUE(woke);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, test::promptly(500ms));
  EXPECT_EQ(server.drain().size(), 1u);
}

// ---- hostile records: each is refused, the client stays usable ----

struct BadCase {
  const char* what;
  std::function<void(CompletionRecord&, const Segment&)> edit;
  bool slot_goes_back;  // the client should return the slot the record hands over
};

TEST(StreamClient, RefusesEveryBadRecordAndKeepsWorking) {
  const std::vector<BadCase> cases = {
      {"slot out of range", [](CompletionRecord& c, const Segment& s) { c.slot = s.slot_count(); }, false},
      {"slot far out of range", [](CompletionRecord& c, const Segment&) { c.slot = 0x7fffffffu; }, false},
      {"byte size beyond the slot", [](CompletionRecord& c, const Segment& s) { c.byte_size = s.slot_bytes() + 1; },
       true},
      {"byte size huge", [](CompletionRecord& c, const Segment&) { c.byte_size = ~0ull - 7; }, true},
      {"byte size zero", [](CompletionRecord& c, const Segment&) { c.byte_size = 0; }, true},
      {"byte size wrong for the mip", [](CompletionRecord& c, const Segment&) { c.byte_size += 4; }, true},
      {"wrong checksum", [](CompletionRecord& c, const Segment&) { c.checksum ^= 1; }, true},
      {"unknown status", [](CompletionRecord& c, const Segment&) { c.status = 99; }, false},
      {"status zero", [](CompletionRecord& c, const Segment&) { c.status = 0; }, false},
      {"unknown format", [](CompletionRecord& c, const Segment&) { c.format = 42; }, true},
      {"format of another texture", [](CompletionRecord& c, const Segment&) { c.format = 2; }, true},
      {"wrong extent", [](CompletionRecord& c, const Segment&) { c.width *= 2; }, true},
      {"zero extent", [](CompletionRecord& c, const Segment&) { c.height = 0; }, true},
      {"mip beyond the texture", [](CompletionRecord& c, const Segment&) { c.mip_level = 40; }, true},
      {"texture outside the table", [](CompletionRecord& c, const Segment&) { c.texture_id = 1000; }, true},
      {"texture not asked for", [](CompletionRecord& c, const Segment&) { c.texture_id = 1; }, true},
      {"generation not the request's", [](CompletionRecord& c, const Segment&) { c.generation += 5; }, true},
      {"error status naming a slot",
       [](CompletionRecord& c, const Segment&) { c.status = static_cast<uint32_t>(CompletionStatus::kNotFound); },
       false},
  };
  for (const BadCase& bc : cases) {
    SCOPED_TRACE(bc.what);
    const Config config = small_config(unique_name("bad"));
    auto client = start_external(config);
    ASSERT_TRUE(client);
    FakeServer server(config.protocol.segment_name);
    RecordingSink sink;
    client->begin_cycle();
    ASSERT_TRUE(client->request(TextureId(0), MipLevel(2), 1));  // 16x16 RGBA8 = 1 KiB
    const auto loads = server.drain();
    ASSERT_EQ(loads.size(), 1u);
    const CompletionRecord sent =
        server.answer(loads[0], shapes()[0], [&](CompletionRecord& c) { bc.edit(c, server.segment()); });
    client->poll(sink, 16);

    const stream::StreamStats st = client->stats();
    EXPECT_EQ(st.protocol_errors, 1u);
    EXPECT_EQ(st.completions_ok, 0u);
    EXPECT_EQ(sink.count(Event::kCommit), 0u) << "nothing unchecked reaches the sink";
    // The request it names (texture 0 mip 2, unless the record names another) is answered badly: rejected,
    // no longer in flight, so the state machine may ask again. A record naming another leaves it in flight.
    const bool names_request = sent.texture_id == 0 && sent.mip_level == 2;
    EXPECT_EQ(st.in_flight, names_request ? 0u : 1u);
    EXPECT_EQ(sink.count(Event::kReject), names_request ? 1u : 0u);
    EXPECT_EQ(st.slots_held, 0u);
    server.drain();
    EXPECT_EQ(server.bad_releases, 0) << "never releases a slot the server owns";
    EXPECT_EQ(server.releases, bc.slot_goes_back ? 1 : 0);
    if (!bc.slot_goes_back && sent.slot < server.segment().slot_count()) server.set_owned(sent.slot, true);

    // Still working: a correct answer streams (to the original request if the bad record named another).
    if (names_request) {
      ASSERT_TRUE(client->request(TextureId(0), MipLevel(2), 1));
      for (const auto& l : server.drain()) server.answer(l, shapes()[0]);
    } else {
      server.answer(loads[0], shapes()[0]);
    }
    client->poll(sink, 16);
    EXPECT_EQ(sink.count(Event::kCommit), 1u);
    EXPECT_TRUE(sink.payload_ok(0, 2));
    EXPECT_EQ(client->stats().server_state, stream::StreamServerState::kExternal);
  }
}

TEST(StreamClient, WrongChecksumHandsTheReservedRoomBack) {
  const Config config = small_config(unique_name("cksum"));
  auto client = start_external(config);
  ASSERT_TRUE(client);
  FakeServer server(config.protocol.segment_name);
  RecordingSink sink;
  client->begin_cycle();
  ASSERT_TRUE(client->request(TextureId(1), MipLevel(3), 1));
  server.answer(server.drain().at(0), shapes()[1], [](CompletionRecord& c) { c.checksum += 1; });
  client->poll(sink, 16);
  ASSERT_EQ(sink.events.size(), 1u);
  EXPECT_EQ(sink.events[0].kind, Event::kReject);
  EXPECT_TRUE(sink.events[0].reserved) << "the reserved span is handed back";
  EXPECT_EQ(client->stats().completions_rejected, 1u);
}

TEST(StreamClient, APayloadChangedAfterPublishingIsRefused) {
  // The server rewrites the slot after publishing the completion (and its checksum). The sink's reserve(),
  // which runs just before the client's one copy, spoils the slot: the copy no longer matches the checksum.
  const Config config = small_config(unique_name("copy"));
  auto client = start_external(config);
  ASSERT_TRUE(client);
  FakeServer server(config.protocol.segment_name);
  struct SpoilingSink : RecordingSink {
    std::span<std::byte> slot;
    std::span<std::byte> reserve(TextureId t, MipLevel m, uint64_t bytes) override {
      slot[0] = ~slot[0];
      return RecordingSink::reserve(t, m, bytes);
    }
  } sink;
  client->begin_cycle();
  ASSERT_TRUE(client->request(TextureId(0), MipLevel(4), 1));
  const CompletionRecord c = server.answer(server.drain().at(0), shapes()[0]);
  sink.slot = server.segment().slot(c.slot);
  client->poll(sink, 16);
  EXPECT_EQ(sink.count(Event::kReject), 1u);
  EXPECT_EQ(sink.count(Event::kCommit), 0u);
}

TEST(StreamClient, ASlotNotYetBackWithTheServerIsNeverAcceptedOrReleasedTwice) {
  const Config config = small_config(unique_name("twice"));
  auto client = start_external(config);
  ASSERT_TRUE(client);
  FakeServer server(config.protocol.segment_name);
  RecordingSink sink;
  client->begin_cycle();
  ASSERT_TRUE(client->request(TextureId(0), MipLevel(4), 1));
  ASSERT_TRUE(client->request(TextureId(0), MipLevel(3), 1));
  const auto loads = server.drain();
  ASSERT_EQ(loads.size(), 2u);
  const CompletionRecord first = server.answer(loads[0], shapes()[0]);
  // The second answer names the slot already handed over with the first.
  server.answer(loads[1], shapes()[0], [&](CompletionRecord& c) { c.slot = first.slot; });
  // The first is held (no room) in poll 1; poll 2 copies it and releases its slot, then meets the second
  // answer naming that slot although the server has not read the release yet: a slot it does not own.
  sink.no_room = 1;
  client->poll(sink, 16);
  EXPECT_EQ(client->stats().slots_held, 1u);
  client->poll(sink, 16);
  EXPECT_EQ(client->stats().protocol_errors, 1u);
  ASSERT_EQ(sink.count(Event::kCommit), 1u);
  EXPECT_TRUE(sink.payload_ok(0, 4));
  ASSERT_EQ(sink.count(Event::kReject), 1u);
  EXPECT_EQ(sink.events[1].mip, 3u);
  server.drain();
  EXPECT_EQ(server.released_per_slot[first.slot], 1) << "released once, not once per record naming it";
  EXPECT_EQ(server.bad_releases, 0);
}

TEST(StreamClient, UnsolicitedAnswersAreRefusedAndTheirSlotReturned) {
  const Config config = small_config(unique_name("unsolicited"));
  auto client = start_external(config);
  ASSERT_TRUE(client);
  FakeServer server(config.protocol.segment_name);
  RecordingSink sink;
  client->begin_cycle();
  RequestRecord fake_load{};
  fake_load.kind = static_cast<uint32_t>(RequestKind::kLoad);
  fake_load.texture_id = 2;
  fake_load.mip_level = 5;
  fake_load.generation = 1;
  server.answer(fake_load, shapes()[2]);
  server.fail(fake_load, CompletionStatus::kTimedOut);
  client->poll(sink, 16);
  EXPECT_EQ(client->stats().protocol_errors, 2u);
  EXPECT_TRUE(sink.events.empty()) << "answers to nothing reach nobody";
  server.drain();
  EXPECT_EQ(server.releases, 1);
  EXPECT_EQ(server.bad_releases, 0);
  // An answer delivered twice: the second is unsolicited.
  ASSERT_TRUE(client->request(TextureId(2), MipLevel(5), 1));
  const auto load = server.drain().at(0);
  server.answer(load, shapes()[2]);
  server.answer(load, shapes()[2]);
  client->poll(sink, 16);
  EXPECT_EQ(sink.count(Event::kCommit), 1u);
  EXPECT_EQ(client->stats().protocol_errors, 3u);
  server.drain();
  EXPECT_EQ(server.owned_count(), 4u);
  EXPECT_EQ(server.bad_releases, 0);
}

TEST(StreamClient, AFloodOfGarbageIsBoundedPerPoll) {
  Config config = small_config(unique_name("flood"));
  auto client = start_external(config);
  ASSERT_TRUE(client);
  FakeServer server(config.protocol.segment_name);
  RecordingSink sink;
  for (int i = 0; i < 64; ++i) {
    CompletionRecord c{};
    c.status = 1000 + static_cast<uint32_t>(i);
    c.slot = kNoSlot;
    server.push_raw(c);
  }
  client->poll(sink, 16);
  EXPECT_EQ(client->stats().protocol_errors, 64u);
  client->poll(sink, 16);
  EXPECT_EQ(client->stats().protocol_errors, 64u);
  EXPECT_TRUE(sink.events.empty());
}

TEST(StreamClient, APositionThatJumpsBreaksTheExternalServerUntilReset) {
  const Config config = small_config(unique_name("jump"));
  auto client = start_external(config);
  ASSERT_TRUE(client);
  auto server = std::make_unique<FakeServer>(config.protocol.segment_name);
  RecordingSink sink;
  client->begin_cycle();
  ASSERT_TRUE(client->request(TextureId(0), MipLevel(4), 1));
  ASSERT_TRUE(client->request(TextureId(1), MipLevel(4), 1));
  server->drain();
  // The completion ring's write position leaps past a whole ring: impossible for an honest producer.
  client->segment().completion_control()->write_pos.v.store(1000, std::memory_order_release);
  client->poll(sink, 16);
  EXPECT_EQ(client->stats().server_state, stream::StreamServerState::kBroken);
  EXPECT_EQ(client->stats().requests_lost, 2u);
  EXPECT_EQ(sink.count(Event::kFailed), 2u);
  for (const Event& e : sink.events) EXPECT_EQ(e.status, CompletionStatus::kCancelled);
  EXPECT_EQ(client->try_request(TextureId(0), MipLevel(4), 1), stream::RequestOutcome::kNoServer);
  client->poll(sink, 16);  // stays broken, reads nothing
  EXPECT_EQ(sink.events.size(), 2u);

  // Reset (the external server has let go); a fresh server attaches and streaming resumes.
  const uint64_t epoch = client->segment().header().epoch;
  server.reset();
  client->reset_external_server(sink);
  EXPECT_NE(client->segment().header().epoch, epoch);
  EXPECT_EQ(client->stats().server_state, stream::StreamServerState::kExternal);
  server = std::make_unique<FakeServer>(config.protocol.segment_name);
  ASSERT_TRUE(client->request(TextureId(0), MipLevel(4), 1));
  for (const auto& l : server->drain()) server->answer(l, shapes()[0]);
  client->poll(sink, 16);
  EXPECT_EQ(sink.count(Event::kCommit), 1u);
  EXPECT_TRUE(sink.payload_ok(0, 4));

  // The request ring's read position (published by the server) jumping ahead is caught on the next push.
  client->segment().request_control()->read_pos.v.store(1u << 20, std::memory_order_release);
  EXPECT_NE(client->try_request(TextureId(2), MipLevel(4), 1), stream::RequestOutcome::kSent);
  client->poll(sink, 16);
  EXPECT_EQ(client->stats().server_state, stream::StreamServerState::kBroken);
}

// ---- the fake server in its own thread, against a frame loop ----

TEST(StreamClient, ConcurrentFakeServerStreamsEveryMipOfEveryTexture) {
  const Config config = small_config(unique_name("thread"));
  auto client = start_external(config);
  ASSERT_TRUE(client);
  std::atomic<bool> stop{false};
  std::atomic<int> bad_releases{0};
  std::atomic<size_t> owned_at_end{0};
  std::thread server_thread([&] {
    FakeServer server(config.protocol.segment_name);
    std::deque<RequestRecord> queue;
    while (!stop.load()) {
      server.beat();
      for (const auto& l : server.drain()) queue.push_back(l);
      // Answer in a different order than asked (back first), as a real scheduler may.
      while (!queue.empty() && server.free_slot() >= 0) {
        server.answer(queue.back(), shapes()[queue.back().texture_id]);
        queue.pop_back();
      }
      std::this_thread::sleep_for(100us);
    }
    server.drain();
    bad_releases = server.bad_releases;
    owned_at_end = server.owned_count();
  });

  stream::TextureStates states(shapes());
  struct StateSink : RecordingSink {
    stream::TextureStates* states = nullptr;
    void commit(TextureId t, MipLevel m, std::span<std::byte> d) override {
      RecordingSink::commit(t, m, d);
      EXPECT_TRUE(states->on_committed(t, m));
    }
    void failed(TextureId t, MipLevel m, CompletionStatus s) override {
      RecordingSink::failed(t, m, s);
      states->on_failed(t, m, s);
    }
    void reject(TextureId t, MipLevel m, std::span<std::byte> r) override {
      RecordingSink::reject(t, m, r);
      states->on_rejected(t, m);
    }
  } sink;
  sink.states = &states;
  const std::vector<stream::StreamCandidate> list{{TextureId(2), 0, 30}, {TextureId(0), 0, 20}, {TextureId(1), 0, 10}};
  const auto deadline = std::chrono::steady_clock::now() + test::kHangAfter;
  while (states.counts().final < 3 || states.counts().pending > 0) {
    ASSERT_LT(std::chrono::steady_clock::now(), deadline) << "streaming did not finish";
    client->begin_cycle();
    (void)states.run_cycle(list, 1 << 20, 0, client->sender());
    client->poll(sink, 4);
    std::this_thread::sleep_for(200us);
  }
  // Give the last releases a moment to reach the server.
  for (int i = 0; i < 50 && client->stats().slots_held > 0; ++i) {
    client->poll(sink, 4);
    std::this_thread::sleep_for(1ms);
  }
  stop = true;
  server_thread.join();
  for (uint32_t t = 0; t < 3; ++t) {
    EXPECT_EQ(states.view(TextureId(t)).resident, 0u);
    for (uint32_t m = 0; m <= stream::initial_mip_level(shapes()[t]); ++m)
      EXPECT_TRUE(sink.payload_ok(t, m)) << t << "/" << m;
  }
  const stream::StreamStats st = client->stats();
  EXPECT_EQ(st.protocol_errors, 0u);
  EXPECT_EQ(st.completions_ok, 5u + 6u + 7u);  // levels 4..0 of 64², 5..0 of 128x32 (4x1 first), 6..0 of BC1 256²
  EXPECT_EQ(st.slots_held, 0u);
  EXPECT_EQ(bad_releases.load(), 0);
  EXPECT_EQ(owned_at_end.load(), 4u) << "every slot is back with the server";
}

// ---- restart: the client spawns a stand-in process, the fake plays the protocol ----

struct TempDir {
  std::filesystem::path path;
  TempDir() {
    path = std::filesystem::temp_directory_path() / unique_name("dir");
    std::filesystem::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
};

std::filesystem::path write_script(const std::filesystem::path& dir, const std::string& name, const std::string& body) {
  const auto p = dir / name;
  std::ofstream(p) << "#!/bin/sh\n" << body << "\n";
  std::filesystem::permissions(p, std::filesystem::perms::owner_all);
  return p;
}

// A virtual clock the test advances by hand.
struct VirtualClock {
  std::shared_ptr<stream::SteadyTime> t = std::make_shared<stream::SteadyTime>(std::chrono::steady_clock::now());
  std::function<stream::SteadyTime()> fn() const {
    return [t = t] { return *t; };
  }
  void advance(std::chrono::milliseconds d) const { *t += d; }
};

template <class Pred>
bool poll_until(stream::StreamClient& client, stream::MipSink& sink, Pred pred, const VirtualClock* clock = nullptr,
                std::chrono::milliseconds step = 0ms) {
  const auto deadline = std::chrono::steady_clock::now() + test::kHangAfter;
  while (std::chrono::steady_clock::now() < deadline) {
    client.poll(sink, 16);
    if (pred()) return true;
    if (clock) clock->advance(step);
    std::this_thread::sleep_for(2ms);
  }
  return false;
}

TEST(StreamClientRestart, ServerDeathLosesInFlightResetsTheSegmentAndRespawns) {
  TempDir dir;
  Config config = small_config(unique_name("death"));
  config.server.executable = write_script(dir.path, "stand-in", "exec sleep 60").string();
  stream::StreamClientOptions opt;
  opt.restart.first_delay = 1ms;
  auto started = stream::StreamClient::start(config, shapes(), dir.path, "", {}, opt);
  ASSERT_TRUE(started.ok()) << started.error().message;
  auto client = std::move(*started);
  RecordingSink sink;
  const int first_pid = client->server_pid();
  ASSERT_GT(first_pid, 0);
  EXPECT_EQ(client->stats().server_state, stream::StreamServerState::kRunning);
  EXPECT_EQ(client->segment().renderer_block().server_epoch.v.load(), client->segment().header().epoch);

  auto server = std::make_unique<FakeServer>(config.protocol.segment_name);
  client->begin_cycle();
  ASSERT_TRUE(client->request(TextureId(0), MipLevel(4), 1));
  ASSERT_TRUE(client->request(TextureId(0), MipLevel(3), 1));
  ASSERT_TRUE(client->request(TextureId(2), MipLevel(6), 1));
  const auto loads = server->drain();
  server->answer(loads[0], shapes()[0]);
  sink.no_room = 1'000'000;  // the answered one stays held by the client until the server has died
  client->poll(sink, 16);
  EXPECT_EQ(client->stats().slots_held, 1u);

  const uint64_t epoch = client->segment().header().epoch;
  ASSERT_EQ(::kill(first_pid, SIGKILL), 0);
  ASSERT_TRUE(poll_until(*client, sink, [&] { return client->stats().server_deaths == 1; }));
  stream::StreamStats st = client->stats();
  EXPECT_EQ(st.requests_lost, 3u);
  EXPECT_EQ(st.in_flight, 0u);
  EXPECT_EQ(st.slots_held, 0u) << "slots of a dead server are not ours to release";
  EXPECT_EQ(sink.count(Event::kFailed), 3u);
  for (const Event& e : sink.events) EXPECT_EQ(e.status, CompletionStatus::kCancelled);
  EXPECT_NE(client->segment().header().epoch, epoch) << "reset after the reap";
  EXPECT_EQ(client->segment().request_control()->write_pos.v.load(), 0u);

  ASSERT_TRUE(poll_until(*client, sink, [&] { return client->server_pid() > 0; }));
  EXPECT_NE(client->server_pid(), first_pid);
  EXPECT_EQ(client->stats().server_restarts, 1u);
  EXPECT_EQ(client->segment().renderer_block().server_epoch.v.load(), client->segment().header().epoch);

  // The next server attaches to the reset segment and serves.
  sink.no_room = 0;
  server = std::make_unique<FakeServer>(config.protocol.segment_name);
  ASSERT_TRUE(client->request(TextureId(0), MipLevel(4), 1));
  for (const auto& l : server->drain()) server->answer(l, shapes()[0]);
  client->poll(sink, 16);
  EXPECT_TRUE(sink.payload_ok(0, 4));
  EXPECT_EQ(server->bad_releases, 0);
}

TEST(StreamClientRestart, AHungServerIsKilledAndReplaced) {
  TempDir dir;
  Config config = small_config(unique_name("hung"));
  config.server.executable = write_script(dir.path, "stand-in", "exec sleep 60").string();
  config.protocol.heartbeat_timeout_ms = 100;
  VirtualClock clock;
  stream::StreamClientOptions opt;
  opt.clock = clock.fn();
  opt.restart.first_delay = 10ms;
  auto started = stream::StreamClient::start(config, shapes(), dir.path, "", {}, opt);
  ASSERT_TRUE(started.ok()) << started.error().message;
  auto client = std::move(*started);
  RecordingSink sink;
  const int pid = client->server_pid();
  FakeServer server(config.protocol.segment_name);  // attached, but its heartbeat never moves

  // Idle: no requests outstanding, so a still heartbeat is fine however long.
  client->poll(sink, 16);
  clock.advance(5000ms);
  client->poll(sink, 16);
  EXPECT_EQ(client->server_pid(), pid);

  client->begin_cycle();
  ASSERT_TRUE(client->request(TextureId(1), MipLevel(2), 1));
  client->poll(sink, 16);
  clock.advance(50ms);
  server.beat();  // progress: the watchdog starts over
  client->poll(sink, 16);
  clock.advance(90ms);
  client->poll(sink, 16);
  EXPECT_EQ(client->stats().server_deaths, 0u);
  clock.advance(20ms);  // 110 ms since the last progress, work outstanding
  client->poll(sink, 16);
  EXPECT_EQ(client->try_request(TextureId(0), MipLevel(4), 1), stream::RequestOutcome::kNoServer) << "being killed";
  ASSERT_TRUE(poll_until(*client, sink, [&] { return client->stats().server_deaths == 1; }));
  EXPECT_EQ(sink.count(Event::kFailed), 1u);
  EXPECT_EQ(client->stats().server_state, stream::StreamServerState::kBackingOff);
  clock.advance(10ms);
  ASSERT_TRUE(poll_until(*client, sink, [&] { return client->server_pid() > 0; }));
  EXPECT_NE(client->server_pid(), pid);
  EXPECT_EQ(client->stats().server_state, stream::StreamServerState::kRunning);
}

TEST(StreamClientRestart, ACorruptRingPositionKillsAndRestartsTheSpawnedServer) {
  TempDir dir;
  Config config = small_config(unique_name("corrupt"));
  config.server.executable = write_script(dir.path, "stand-in", "exec sleep 60").string();
  stream::StreamClientOptions opt;
  opt.restart.first_delay = 1ms;
  auto started = stream::StreamClient::start(config, shapes(), dir.path, "", {}, opt);
  ASSERT_TRUE(started.ok()) << started.error().message;
  auto client = std::move(*started);
  RecordingSink sink;
  const int pid = client->server_pid();
  client->begin_cycle();
  ASSERT_TRUE(client->request(TextureId(0), MipLevel(4), 1));
  client->segment().completion_control()->write_pos.v.store(12345, std::memory_order_release);
  ASSERT_TRUE(
      poll_until(*client, sink, [&] { return client->stats().server_deaths == 1 && client->server_pid() > 0; }));
  EXPECT_NE(client->server_pid(), pid);
  EXPECT_EQ(client->stats().requests_lost, 1u);
  EXPECT_GE(client->stats().protocol_errors, 1u);
  EXPECT_EQ(client->segment().completion_control()->write_pos.v.load(), 0u);
}

TEST(StreamClientRestart, MissingServerExecutableIsAStartError) {
  Config config = small_config(unique_name("noexe"));
  config.server.executable = "/nonexistent/texstream-server";
  auto c = stream::StreamClient::start(config, shapes(), "/tmp", "", {}, {});
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.error().message.find("/nonexistent/texstream-server"), std::string::npos) << c.error().message;
  EXPECT_NE(c.error().message.find("server.executable"), std::string::npos) << c.error().message;
  EXPECT_FALSE(std::filesystem::exists("/dev/shm/" + config.protocol.segment_name)) << "no segment left behind";
}

TEST(StreamClientRestart, DestroyingTheClientKillsTheServerAndRemovesTheSegment) {
  TempDir dir;
  Config config = small_config(unique_name("dtor"));
  config.server.executable = write_script(dir.path, "stand-in", "exec sleep 60").string();
  auto started = stream::StreamClient::start(config, shapes(), dir.path, "", {}, {});
  ASSERT_TRUE(started.ok()) << started.error().message;
  const int pid = (*started)->server_pid();
  ASSERT_GT(pid, 0);
  const auto start_time = process_start_time(pid);
  ASSERT_TRUE(start_time.has_value());
  EXPECT_TRUE(std::filesystem::exists("/dev/shm/" + config.protocol.segment_name));
  started = make_error(ErrorCode::kNotFound, "destroyed");  // drops the client
  EXPECT_FALSE(process_alive(pid, *start_time));
  EXPECT_FALSE(std::filesystem::exists("/dev/shm/" + config.protocol.segment_name));
}

}  // namespace
}  // namespace texstream
