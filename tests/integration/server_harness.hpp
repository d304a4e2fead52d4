#pragma once
// The renderer's side of one shared segment with a texstream Server running in a thread of this process, for
// the storage tests and `texstream-bench storage`: push loads, poll completions (kOk slots are released at
// once), with any Storage stack behind the server.
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/protocol/renderer_endpoint.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/server/dispatch/server.hpp"
#include "texstream/server/storage/storage.hpp"

namespace texstream::test {

class ServerHarness {
 public:
  // 32 slots of 1 MiB: the protocol defaults (config.hpp).
  static std::unique_ptr<ServerHarness> start(const std::filesystem::path& scene, const ServerConfig& config,
                                              server::Storage& storage, std::string& error, uint32_t slot_count = 32,
                                              uint64_t slot_bytes = 1u << 20) {
    static std::atomic<int> counter{0};
    auto h = std::unique_ptr<ServerHarness>(new ServerHarness());
    SegmentParams params;
    params.slot_count = slot_count;
    params.slot_bytes = slot_bytes;
    auto seg =
        Segment::create("texstream-storage-" + std::to_string(::getpid()) + "-" + std::to_string(counter++), params);
    if (!seg.ok()) {
      error = seg.error().message;
      return nullptr;
    }
    h->segment_ = std::move(seg).value();
    h->endpoint_ = RendererEndpoint(*h->segment_);
    auto server = server::Server::create(*h->segment_, scene, config, storage);
    if (!server.ok()) {
      error = server.error().message;
      return nullptr;
    }
    h->server_ = std::move(server).value();
    h->thread_ = std::thread([p = h.get()] { p->server_->run(p->stop_); });
    return h;
  }

  // Only the segment and the renderer's side: the server is another process (texstream-server --segment
  // segment_name()).
  static std::unique_ptr<ServerHarness> create_segment_only(std::string& error, uint32_t slot_count = 32,
                                                            uint64_t slot_bytes = 1u << 20) {
    static std::atomic<int> counter{0};
    auto h = std::unique_ptr<ServerHarness>(new ServerHarness());
    SegmentParams params;
    params.slot_count = slot_count;
    params.slot_bytes = slot_bytes;
    auto seg = Segment::create("texstream-storage-proc-" + std::to_string(::getpid()) + "-" + std::to_string(counter++),
                               params);
    if (!seg.ok()) {
      error = seg.error().message;
      return nullptr;
    }
    h->segment_ = std::move(seg).value();
    h->endpoint_ = RendererEndpoint(*h->segment_);
    return h;
  }

  ~ServerHarness() {
    stop_ = true;
    Doorbell(*segment_).wake_all();  // the server thread sees stop_ when it wakes
    if (thread_.joinable()) thread_.join();
    server_.reset();
  }

  const std::string& segment_name() const { return segment_->name(); }
  server::Server& server() { return *server_; }
  const ServerBlock& server_block() const { return segment_->server_block(); }

  bool push(uint32_t texture, uint32_t mip, uint64_t generation, float priority) {
    return endpoint_.push_load(TextureId(texture), MipLevel(mip), Generation(generation), priority);
  }

  bool push_page(uint32_t file, pages::PageId page, uint64_t generation, float priority) {
    return endpoint_.push_load_page(file, page, Generation(generation), priority);
  }

  void ring() { endpoint_.ring(); }

  // Calls on(completion, payload) for every completion now waiting (payload empty unless kOk), releases the
  // kOk slots, rings. Returns how many.
  template <class F>
  uint32_t poll(F&& on) {
    uint32_t n = 0;
    endpoint_.flush_releases();
    while (std::optional<CompletionRecord> c = endpoint_.poll()) {
      ++n;
      std::span<const std::byte> payload;
      if (c->status == static_cast<uint32_t>(CompletionStatus::kOk)) {
        payload = segment_->slot(c->slot).first(c->byte_size);
      }
      on(*c, payload);
      if (c->status == static_cast<uint32_t>(CompletionStatus::kOk)) endpoint_.release(SlotIndex(c->slot));
    }
    endpoint_.flush_releases();
    endpoint_.ring();
    return n;
  }

 private:
  ServerHarness() = default;

  std::unique_ptr<Segment> segment_;
  RendererEndpoint endpoint_;  // the renderer's end, as StreamClient uses it
  std::unique_ptr<server::Server> server_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace texstream::test

namespace texstream::test {

struct WantedMip {
  uint32_t texture;
  uint32_t mip;
  float priority;
};

struct DriveResult {
  uint64_t ok = 0;
  uint64_t bytes = 0;     // kOk payload bytes
  uint64_t errors = 0;    // final non-kOk answers
  uint64_t unfilled = 0;  // kUnfilled answers (asked again)
  uint64_t cycles = 0;
  double first_ok_s = -1;          // time to the first kOk
  double seconds = 0;              // until every mip had a final answer, or the deadline
  bool complete = false;           // every mip had a final answer
  std::vector<uint32_t> status;    // per wanted mip: its final CompletionStatus, or kUnfilled if none came
  std::vector<uint64_t> checksum;  // per wanted mip: kOk's checksum
};

// Plays a renderer's streaming cycles: every `cycle` (one generation each) it asks for every wanted mip that
// has no final answer and is not outstanding, at most `window` outstanding. kUnfilled and kCancelled are
// asked again next cycle (seed 002's feedback path); every other status is final. Stops when all are final
// or at `deadline`.
// `timeline`, when given, gets (seconds since start, kOk bytes so far, kOk mips so far) at each kOk.
struct TimelinePoint {
  double seconds;
  uint64_t bytes;
  uint64_t mips;
};
inline DriveResult drive(ServerHarness& h, const std::vector<WantedMip>& wanted, std::chrono::milliseconds deadline,
                         uint32_t window = 16, std::chrono::microseconds cycle = std::chrono::milliseconds(5),
                         std::vector<TimelinePoint>* timeline = nullptr) {
  DriveResult r;
  r.status.assign(wanted.size(), static_cast<uint32_t>(CompletionStatus::kUnfilled));
  r.checksum.assign(wanted.size(), 0);
  std::vector<uint8_t> state(wanted.size(), 0);  // 0 wanted, 1 outstanding, 2 final
  std::unordered_map<uint64_t, size_t> index;
  for (size_t i = 0; i < wanted.size(); ++i) index[(uint64_t(wanted[i].texture) << 32) | wanted[i].mip] = i;
  const auto t0 = std::chrono::steady_clock::now();
  auto next_cycle = t0;
  uint64_t generation = 1;
  size_t finals = 0;
  uint32_t outstanding = 0;
  while (finals < wanted.size()) {
    const auto now = std::chrono::steady_clock::now();
    if (now - t0 > deadline) break;
    if (now >= next_cycle) {
      ++generation;
      ++r.cycles;
      for (size_t i = 0; i < wanted.size() && outstanding < window; ++i) {
        if (state[i] != 0) continue;
        if (!h.push(wanted[i].texture, wanted[i].mip, generation, wanted[i].priority)) break;
        state[i] = 1;
        ++outstanding;
      }
      h.ring();
      next_cycle = now + cycle;
    }
    const uint32_t n = h.poll([&](const CompletionRecord& c, std::span<const std::byte>) {
      auto it = index.find((uint64_t(c.texture_id) << 32) | c.mip_level);
      if (it == index.end() || state[it->second] != 1) return;
      const size_t i = it->second;
      --outstanding;
      const auto status = static_cast<CompletionStatus>(c.status);
      if (status == CompletionStatus::kUnfilled || status == CompletionStatus::kCancelled) {
        if (status == CompletionStatus::kUnfilled) ++r.unfilled;
        state[i] = 0;
        return;
      }
      state[i] = 2;
      ++finals;
      r.status[i] = c.status;
      if (status == CompletionStatus::kOk) {
        ++r.ok;
        r.bytes += c.byte_size;
        r.checksum[i] = c.checksum;
        const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (r.first_ok_s < 0) r.first_ok_s = t;
        if (timeline) timeline->push_back({t, r.bytes, r.ok});
      } else {
        ++r.errors;
      }
    });
    if (n == 0) std::this_thread::sleep_for(std::chrono::microseconds(100));
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.complete = finals == wanted.size();
  return r;
}

}  // namespace texstream::test
