// Issue 9, server-process level quarantine: a StreamClient that spawns a stand-in server
// (quarantine_fake_server.cpp) which records the texture it is loading in ServerBlock::loading and dies by
// a signal on one texture. After two crash-signal deaths while that texture was loading, the client stops
// requesting it (kQuarantined, failed with kCorrupt so the texture states leave it on its colormap) and the
// server stops dying; a texture that was loading during one crash only is served on; deaths by SIGKILL
// (the watchdog, texstream-chaos, the OOM killer) never quarantine anything. Last, the same with the real
// texstream-server: its load worker records the texture in ServerBlock::loading (worker_pool.cpp; the
// server passes the words to its WorkerPool in server.cpp), and a SIGSEGV while it loads one texture, twice,
// quarantines that texture while the other is served.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "../support/patience.hpp"
#include "scoped_env.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/stream/stream_client.hpp"

namespace texstream {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

const fs::path kFakeServer = fs::path(TEXSTREAM_BIN_DIR) / "quarantine_fake_server";

using test::ScopedEnv;

class RecordingSink : public stream::MipSink {
 public:
  std::span<std::byte> reserve(TextureId, MipLevel, uint64_t) override { return {}; }
  void commit(TextureId t, MipLevel m, std::span<std::byte>) override {
    ADD_FAILURE() << "the fake server sends no payloads: texture " << t.value << " mip " << m.value;
  }
  void reject(TextureId t, MipLevel m, std::span<std::byte>) override {
    ADD_FAILURE() << "rejected texture " << t.value << " mip " << m.value;
  }
  void failed(TextureId t, MipLevel m, CompletionStatus s) override {
    if (s == CompletionStatus::kCancelled) {
      ++cancelled;  // lost with a dead server: asked again
      return;
    }
    final_status[{t.value, m.value}] = s;
  }
  // The final answer for (texture, mip), or kUnfilled if none came.
  CompletionStatus status(uint32_t t, uint32_t m) const {
    const auto it = final_status.find({t, m});
    return it == final_status.end() ? CompletionStatus::kUnfilled : it->second;
  }
  bool answered(uint32_t t, uint32_t m) const { return final_status.count({t, m}) != 0; }
  std::map<std::pair<uint32_t, uint32_t>, CompletionStatus> final_status;
  int cancelled = 0;
};

struct Fixture {
  fs::path dir;
  Config config;
  std::vector<TextureShape> shapes;

  explicit Fixture(const std::string& tag) {
    dir = fs::temp_directory_path() / ("texstream-crash-quarantine-" + tag + "-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    config.protocol.segment_name = "texstream-test-quarantine-" + tag + "-" + std::to_string(::getpid());
    config.protocol.staging_slot_count = 4;
    config.server.executable = kFakeServer.string();
    for (int i = 0; i < 4; ++i) shapes.push_back({16, 16, 5, TexelFormat::kRgba8});
  }
  ~Fixture() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  std::unique_ptr<stream::StreamClient> start() {
    auto started = stream::StreamClient::start(config, shapes, dir, "", {}, {});
    EXPECT_TRUE(started.ok()) << started.error().message;
    return started.ok() ? std::move(*started) : nullptr;
  }
};

// Asks for mip 0 of every texture without a final answer (and not in flight), then polls, until `done` or
// the deadline.
template <class Done>
bool drive(stream::StreamClient& client, RecordingSink& sink, uint32_t textures, std::chrono::seconds deadline,
           Done done) {
  const auto end = Clock::now() + deadline;
  while (Clock::now() < end) {
    client.begin_cycle();
    for (uint32_t t = 0; t < textures; ++t) {
      if (!sink.answered(t, 0) && !client.in_flight(TextureId(t), MipLevel(0))) {
        (void)client.try_request(TextureId(t), MipLevel(0), 1.0f);
      }
    }
    client.poll(sink, 8);
    if (done()) return true;
    std::this_thread::sleep_for(2ms);
  }
  return false;
}

// Drives mip 0 of textures 0..3 until each has a final answer: texture 2 (the fake server's bad one) must be
// quarantined (kCorrupt), the others answered by the server (kNotFound: the fake has no files).
void expect_texture_2_quarantined(stream::StreamClient& client, RecordingSink& sink) {
  const bool answered = drive(client, sink, 4, test::kHangAfter, [&] { return sink.final_status.size() == 4; });
  const stream::StreamStats st = client.stats();
  ASSERT_TRUE(answered) << "not every texture got a final answer: " << sink.final_status.size() << " of 4; "
                        << st.server_deaths << " server deaths, state " << to_string(st.server_state);
  EXPECT_EQ(sink.status(2, 0), CompletionStatus::kCorrupt);
  for (uint32_t t : {0u, 1u, 3u}) EXPECT_EQ(sink.status(t, 0), CompletionStatus::kNotFound) << t;
  EXPECT_TRUE(client.quarantined(TextureId(2)));
}

// Drives mip 0 of textures 0..3 until the server (which dies whenever texture 2 is loaded) has died 3 times:
// texture 2 must never be quarantined and must still be asked for.
void expect_three_deaths_without_quarantine(stream::StreamClient& client, RecordingSink& sink) {
  const bool died = drive(client, sink, 4, test::kHangAfter, [&] { return client.stats().server_deaths >= 3; });
  const stream::StreamStats st = client.stats();
  ASSERT_TRUE(died) << st.server_deaths << " deaths";
  EXPECT_FALSE(client.quarantined(TextureId(2)));
  EXPECT_EQ(st.textures_quarantined, 0u);
  EXPECT_FALSE(sink.answered(2, 0)) << "texture 2 must still be asked for";
}

TEST(StreamCrashQuarantine, ATextureLoadingDuringTwoCrashesIsQuarantinedAndTheOthersAreServed) {
  ASSERT_EQ(::access(kFakeServer.c_str(), X_OK), 0) << kFakeServer;
  Fixture f("segv");
  ScopedEnv crash("TEXSTREAM_FAKE_CRASH_TEXTURE", "2");
  ScopedEnv bystander("TEXSTREAM_FAKE_BYSTANDER", "1");
  ScopedEnv mark("TEXSTREAM_FAKE_MARK", (f.dir / "bystander-recorded").string());
  auto client = f.start();
  ASSERT_TRUE(client);
  RecordingSink sink;
  ASSERT_NO_FATAL_FAILURE(expect_texture_2_quarantined(*client, sink));
  const stream::StreamStats st = client->stats();
  EXPECT_FALSE(client->quarantined(TextureId(1))) << "charged for one crash only";
  EXPECT_EQ(st.crash_signal_deaths, 2u);
  EXPECT_EQ(st.server_deaths, 2u);
  EXPECT_EQ(st.textures_quarantined, 1u);
  // What the run summary names (textures charged and quarantined).
  EXPECT_EQ(client->quarantine().quarantined_ids(), std::vector<uint32_t>{2});
  EXPECT_EQ(client->quarantine().charged_ids(), (std::vector<uint32_t>{1, 2})) << "the bystander was charged once";

  // Quarantined: another mip is refused without being sent and fails for good at the next poll; the server
  // lives on.
  EXPECT_EQ(client->try_request(TextureId(2), MipLevel(1), 1.0f), stream::RequestOutcome::kQuarantined);
  EXPECT_EQ(client->try_request(TextureId(2), MipLevel(1), 1.0f), stream::RequestOutcome::kQuarantined);
  EXPECT_FALSE(client->in_flight(TextureId(2), MipLevel(1)));
  client->poll(sink, 8);
  EXPECT_EQ(sink.status(2, 1), CompletionStatus::kCorrupt);
  const uint64_t sent = client->stats().requests_sent;
  // Texture 3's mip 1 still goes to the (same) server and is answered.
  const auto end = Clock::now() + test::kHangAfter;
  ASSERT_EQ(client->try_request(TextureId(3), MipLevel(1), 1.0f), stream::RequestOutcome::kSent);
  while (!sink.answered(3, 1) && Clock::now() < end) {
    client->poll(sink, 8);
    std::this_thread::sleep_for(2ms);
  }
  EXPECT_EQ(sink.status(3, 1), CompletionStatus::kNotFound);
  EXPECT_EQ(client->stats().requests_sent, sent + 1);
  EXPECT_EQ(client->stats().server_deaths, 2u);
  EXPECT_NE(client->stats_text().find("textures_quarantined 1\n"), std::string::npos) << client->stats_text();

  // What the renderer's texture states make of it: the quarantined texture is taken as sent, fails with
  // kCorrupt at the next poll and is broken (colormap only, never asked for again).
  class StatesSink : public RecordingSink {
   public:
    explicit StatesSink(stream::TextureStates& s) : states(s) {}
    void failed(TextureId t, MipLevel m, CompletionStatus st) override {
      RecordingSink::failed(t, m, st);
      states.on_failed(t, m, st);
    }
    stream::TextureStates& states;
  };
  stream::TextureStates states(f.shapes);
  StatesSink states_sink(states);
  const std::vector<stream::StreamCandidate> wanted{{TextureId(2), 0.0f, 1.0f}};
  client->begin_cycle();
  const stream::CycleResult cycle = states.run_cycle(wanted, 1 << 20, 0.0f, client->sender());
  ASSERT_EQ(cycle.sent.size(), 1u);
  EXPECT_TRUE(states.view(TextureId(2)).pending.has_value());
  client->poll(states_sink, 8);
  EXPECT_TRUE(states.view(TextureId(2)).broken);
  client->begin_cycle();
  EXPECT_TRUE(states.run_cycle(wanted, 1 << 20, 0.0f, client->sender()).sent.empty());
}

TEST(StreamCrashQuarantine, DeathsBySigkillNeverQuarantine) {
  ASSERT_EQ(::access(kFakeServer.c_str(), X_OK), 0) << kFakeServer;
  Fixture f("kill");
  ScopedEnv crash("TEXSTREAM_FAKE_CRASH_TEXTURE", "2");
  ScopedEnv how("TEXSTREAM_FAKE_CRASH_SIGNAL", std::to_string(SIGKILL));
  auto client = f.start();
  ASSERT_TRUE(client);
  RecordingSink sink;
  // Texture 2 kills the server every time it is asked for.
  ASSERT_NO_FATAL_FAILURE(expect_three_deaths_without_quarantine(*client, sink));
  EXPECT_EQ(client->stats().crash_signal_deaths, 0u);
  EXPECT_GE(sink.cancelled, 3);
}

// The fake server, set to stall whenever texture 2 is loaded (`mode`: its hang or its stop variable), under
// a 300 ms heartbeat timeout so that the watchdog kills it soon.
struct StallingServer {
  Fixture f;
  ScopedEnv stall;
  std::unique_ptr<stream::StreamClient> client;
  StallingServer(const std::string& tag, const char* mode) : f(tag), stall(mode, "2") {
    f.config.protocol.heartbeat_timeout_ms = 300;
    client = f.start();
  }
};

// A server that hangs while loading a texture (a file whose reads block, a stuck mount) is killed by the
// heartbeat watchdog, and that kill charges the texture like a crash: after two, it is quarantined and the
// others are served. Before, only crash signals charged: the watchdog killed the server, the next one hung on
// the same texture, for ever (seen with a FIFO in place of a texture file, docs/faults.md).
TEST(StreamCrashQuarantine, ATextureLoadingDuringTwoHangsIsQuarantined) {
  ASSERT_EQ(::access(kFakeServer.c_str(), X_OK), 0) << kFakeServer;
  StallingServer s("hang", "TEXSTREAM_FAKE_HANG_TEXTURE");
  ASSERT_TRUE(s.client);
  RecordingSink sink;
  ASSERT_NO_FATAL_FAILURE(expect_texture_2_quarantined(*s.client, sink));
  const stream::StreamStats st = s.client->stats();
  EXPECT_EQ(st.crash_signal_deaths, 0u) << "a hang is no crash signal";
  EXPECT_EQ(st.server_deaths, 2u);
  EXPECT_EQ(st.textures_quarantined, 1u);
}

// A server stopped from outside (SIGSTOP: texstream-chaos, a debugger) while loading a texture is killed by
// the watchdog too, but that is not the texture's doing: it is never charged.
TEST(StreamCrashQuarantine, AStoppedServerIsNotChargedToTheTextureItWasLoading) {
  ASSERT_EQ(::access(kFakeServer.c_str(), X_OK), 0) << kFakeServer;
  StallingServer s("stop", "TEXSTREAM_FAKE_STOP_TEXTURE");
  ASSERT_TRUE(s.client);
  RecordingSink sink;
  ASSERT_NO_FATAL_FAILURE(expect_three_deaths_without_quarantine(*s.client, sink));
}

// $TEXSTREAM_SERVER, else this build's texstream-server (a build dependency of this test).
fs::path real_server() {
  if (const char* env = std::getenv("TEXSTREAM_SERVER"); env && *env) return env;
  return fs::path(TEXSTREAM_BIN_DIR) / "texstream-server";
}

// Two 1024x1024 RGBA8 textures in the generator's DDS layout (read in-process, no decode helper).
void write_scene(const fs::path& dir, const std::vector<scene::TextureRecord>& textures) {
  scene::Manifest m;
  m.name = "crash-quarantine";
  m.mesh_count = 0;
  m.texture_count = textures.size();
  ASSERT_TRUE(scene::write_manifest(dir, m).ok());
  ASSERT_TRUE(scene::write_meshes(dir, scene::MeshData{}).ok());
  ASSERT_TRUE(scene::write_texture_table(dir, textures).ok());
  ASSERT_TRUE(scene::write_colormap(dir, std::vector<uint32_t>(textures.size(), 0xff808080u)).ok());
  for (uint32_t id = 0; id < textures.size(); ++id) {
    const auto& t = textures[id];
    const auto f = static_cast<TexelFormat>(t.format);
    const auto header = scene::make_dds_header(f, t.width, t.height, t.mip_count);
    std::vector<char> bytes;
    for (auto b : header) bytes.push_back(static_cast<char>(b));
    const size_t header_bytes = bytes.size();
    bytes.resize(scene::dds_file_bytes(f, t.width, t.height, t.mip_count));
    for (size_t i = header_bytes; i < bytes.size(); ++i) bytes[i] = static_cast<char>((i * 7 + id * 101) & 0xff);
    const fs::path path = scene::texture_path(dir, TextureId(id));
    fs::create_directories(path.parent_path());
    std::ofstream(path, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }
}

TEST(StreamCrashQuarantine, TheRealServerRecordsTheTextureItLoadsAndTwoCrashesOnItQuarantineIt) {
  const fs::path server = real_server();
  ASSERT_EQ(::access(server.c_str(), X_OK), 0) << server;
  Fixture f("real");
  const uint32_t mips = full_mip_count(1024, 1024);
  const std::vector<scene::TextureRecord> textures(2, {1024, 1024, mips, static_cast<uint32_t>(TexelFormat::kRgba8)});
  write_scene(f.dir, textures);
  f.shapes.assign(2, {1024, 1024, mips, TexelFormat::kRgba8});
  f.config.server.executable = server.string();
  f.config.protocol.staging_slot_bytes = 4 << 20;  // mip 0 of 1024x1024 RGBA8
  // Only the two SIGSEGVs may end a server: on a busy machine a starved heartbeat must not count as a hang.
  f.config.protocol.heartbeat_timeout_ms = 10 * Config{}.protocol.heartbeat_timeout_ms;
  // 0.1 MB/s: reading a 4 MiB mip 0 waits >= 30 s in the token bucket, inside the load worker, with its
  // texture recorded: the window in which the test crashes the server. At 1 MB/s (~3 s) it closed under ASan
  // on a busy machine while ASan was still reporting the SIGSEGV: the death then named no texture.
  const std::vector<std::string> overrides{"protocol.staging_slot_bytes=4194304", "server.worker_threads=1",
                                           "server.rate_limit_mb_s=0.1", "server.log_level=warn"};
  // The servers inherit this: the SIGSEGVs below leave no core files.
  const rlimit no_core{0, 0};
  ASSERT_EQ(::setrlimit(RLIMIT_CORE, &no_core), 0);
  auto started = stream::StreamClient::start(f.config, f.shapes, f.dir, "", overrides, {});
  ASSERT_TRUE(started.ok()) << started.error().message;
  auto client = std::move(*started);
  RecordingSink sink;

  for (int crash = 1; crash <= 2; ++crash) {
    // Ask for texture 1's mip 0 (again: the request was lost with the server) until the server's load worker
    // is on it, then crash the server as a bug in its reader would.
    const auto end = Clock::now() + test::kHangAfter;
    bool loading = false;
    while (!loading && Clock::now() < end) {
      client->begin_cycle();
      if (!client->in_flight(TextureId(1), MipLevel(0))) (void)client->try_request(TextureId(1), MipLevel(0), 1.0f);
      client->poll(sink, 8);
      loading = client->segment().server_block().loading[0].v.load(std::memory_order_relaxed) == 2;
      if (!loading) std::this_thread::sleep_for(1ms);
    }
    ASSERT_TRUE(loading) << "crash " << crash << ": ServerBlock::loading[0] never named texture 1 (does the server "
                         << "pass the words to its WorkerPool? server.cpp)";
    const uint64_t deaths = client->stats().server_deaths;
    ASSERT_EQ(::kill(client->server_pid(), SIGSEGV), 0);
    const auto told_by = Clock::now() + test::kHangAfter;
    while (client->stats().server_deaths == deaths && Clock::now() < told_by) {
      client->poll(sink, 8);
      std::this_thread::sleep_for(1ms);
    }
    ASSERT_EQ(client->stats().server_deaths, deaths + 1) << "crash " << crash;
  }
  EXPECT_TRUE(client->quarantined(TextureId(1)));
  EXPECT_FALSE(client->quarantined(TextureId(0)));
  EXPECT_EQ(sink.status(1, 0), CompletionStatus::kCorrupt);
  EXPECT_EQ(client->stats().crash_signal_deaths, 2u);
  EXPECT_EQ(client->try_request(TextureId(1), MipLevel(5), 1.0f), stream::RequestOutcome::kQuarantined);

  // The next server serves texture 0 (a small mip: no rate-limit wait) and is never asked for texture 1.
  class CountingSink : public RecordingSink {
   public:
    std::span<std::byte> reserve(TextureId, MipLevel, uint64_t bytes) override {
      buffer.assign(bytes, std::byte{0});
      return buffer;
    }
    void commit(TextureId t, MipLevel m, std::span<std::byte>) override {
      final_status[{t.value, m.value}] = CompletionStatus::kOk;
    }
    std::vector<std::byte> buffer;
  } served;
  const auto end = Clock::now() + test::kHangAfter;
  while (!served.answered(0, 5) && Clock::now() < end) {
    client->begin_cycle();
    if (!client->in_flight(TextureId(0), MipLevel(5))) (void)client->try_request(TextureId(0), MipLevel(5), 1.0f);
    client->poll(served, 8);
    std::this_thread::sleep_for(1ms);
  }
  EXPECT_EQ(served.status(0, 5), CompletionStatus::kOk);
  EXPECT_EQ(served.status(1, 5), CompletionStatus::kCorrupt);  // the refused request, failed at the poll
  EXPECT_EQ(client->stats().server_deaths, 2u);
}

}  // namespace
}  // namespace texstream
