// libFuzzer: StreamClient's record handling over a real segment. The fuzzer plays the server: each input is
// a list of 64-byte completion records (and a few slot bytes) pushed into the completion ring after the
// client has sent some requests — mips, and pages of a two-level page file in memory (seed page_ok.bin
// answers the root) — then the client polls. Invariants: no crash or sanitizer report, a commit is exactly
// the payload the "server" put in the slot (a page's exactly its index entry's size), and the client never
// holds more slots than exist.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <memory>

#include "../support/memory_page_file.hpp"
#include "texstream/protocol/checksum.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/stream/stream_client.hpp"

using namespace texstream;

namespace {

std::vector<TextureShape> shapes() {
  return {{64, 64, 7, TexelFormat::kRgba8}, {128, 32, 8, TexelFormat::kRgba8}, {256, 256, 9, TexelFormat::kBc1}};
}

class Sink : public stream::MipSink {
 public:
  std::span<std::byte> reserve(TextureId, MipLevel, uint64_t bytes) override {
    buf_.assign(bytes, std::byte{0});
    return buf_;
  }
  void commit(TextureId, MipLevel, std::span<std::byte> data) override {
    if (data.size() > buf_.size()) __builtin_trap();
  }
  void reject(TextureId, MipLevel, std::span<std::byte>) override {}
  void failed(TextureId, MipLevel, CompletionStatus) override {}

 private:
  std::vector<std::byte> buf_;
};

class Pages : public stream::PageSink {
 public:
  std::span<std::byte> reserve_page(uint32_t, pages::PageId, uint64_t bytes) override {
    buf_.assign(bytes, std::byte{0});
    return buf_;
  }
  void commit_page(uint32_t file, pages::PageId page, std::span<std::byte> data) override {
    if (file != 0 || data.size() != 256 || data.size() > buf_.size() || page.level > 1) __builtin_trap();
  }
  void page_failed(uint32_t, pages::PageId, CompletionStatus) override {}

 private:
  std::vector<std::byte> buf_;
};

struct Rig {
  test::MemoryPageFile page_file{2};
  std::unique_ptr<stream::StreamClient> client;
  std::unique_ptr<Segment> server_side;
  SpscRingConsumer<RequestRecord> requests;
  SpscRingProducer<CompletionRecord> completions;
  Rig() {
    Config c;
    c.protocol.segment_name = "texstream-fuzz-" + std::to_string(::getpid());
    c.protocol.request_ring_capacity = 64;
    c.protocol.completion_ring_capacity = 64;
    c.stream.max_requests_in_flight = 48;  // must not exceed the request ring (config validate())
    c.protocol.staging_slot_count = 4;
    c.protocol.staging_slot_bytes = 64 << 10;
    c.cache.layer_extent_px = 64;
    stream::StreamClientOptions o;
    o.spawn_server = false;
    auto started = stream::StreamClient::start(c, shapes(), "/nonexistent", "", {}, o);
    if (!started) {  // a harness bug, not a finding: say why before stopping
      std::fprintf(stderr, "fuzz_stream_client: stream::StreamClient::start failed: %s\n",
                   started.error().message.c_str());
      __builtin_trap();
    }
    client = std::move(*started);
    auto seg = Segment::open(c.protocol.segment_name);
    if (!seg) __builtin_trap();
    server_side = std::move(*seg);
    attach();
    if (page_file.file == nullptr) __builtin_trap();  // a harness bug
  }
  void attach() {
    requests = server_side->request_consumer();
    completions = server_side->completion_producer();
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static Rig rig;  // one segment for the whole run (removed by the client's destructor at exit)
  static Sink sink;
  static Pages page_sink;
  static const bool registered = [] {
    rig.client->set_page_files({rig.page_file.file}, &page_sink);
    return true;
  }();
  (void)registered;
  rig.client->begin_cycle();
  uint64_t last_generation = 0;
  for (uint32_t t = 0; t < 3; ++t)
    for (uint32_t m = 0; m < 4; ++m) (void)rig.client->try_request(TextureId(t), MipLevel(m), 1.0f);
  for (const pages::PageId p : {pages::PageId{0, 0, 0}, pages::PageId{1, 1, 0}, pages::PageId{1, 0, 1}}) {
    (void)rig.client->try_request_page(0, p, 1.0f);
  }
  while (auto r = rig.requests.try_pop()) last_generation = r->generation;
  // Records: each 64 bytes from the input; a record whose generation is 0 gets the live one (so that some
  // pass the "did we ask" check), and whose checksum is 0 gets the real checksum of its slot bytes.
  for (size_t off = 0; off + sizeof(CompletionRecord) <= size; off += sizeof(CompletionRecord)) {
    CompletionRecord c;
    std::memcpy(&c, data + off, sizeof c);
    if (c.generation == 0) c.generation = last_generation;
    if (c.checksum == 0 && c.slot < rig.server_side->slot_count()) {
      auto s = rig.server_side->slot(c.slot);
      c.checksum = payload_checksum(s.data(), std::min<uint64_t>(c.byte_size, s.size()));
    }
    if (!rig.completions.try_push(c)) break;
  }
  rig.client->poll(sink, 64);
  if (rig.client->stats().slots_held > rig.server_side->slot_count()) __builtin_trap();
  if (rig.client->stats().server_state == stream::StreamServerState::kBroken) {
    rig.client->reset_external_server(sink);
    rig.attach();
  }
  return 0;
}
