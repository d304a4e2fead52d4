// End to end with the real texstream-server: a tiny scene written with the scene_format writers, a
// StreamClient that spawns the server, and TextureStates driving cycles until every texture is resident at
// level 0. Every payload is compared with the bytes of its mip in the DDS file. Skipped (with a message)
// only if no texstream-server binary has been built.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <thread>
#include <vector>

#include "texstream/common/scene_format.hpp"
#include "texstream/stream/stream_client.hpp"

namespace texstream {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

// $TEXSTREAM_SERVER, else this build's bin/, else the server engineer's and the main build dirs.
fs::path find_server() {
  if (const char* env = std::getenv("TEXSTREAM_SERVER"); env && *env) return env;
  for (const fs::path& p : {fs::path(TEXSTREAM_BIN_DIR) / "texstream-server",
                            fs::path(TEXSTREAM_SOURCE_DIR) / "build-server/bin/texstream-server",
                            fs::path(TEXSTREAM_SOURCE_DIR) / "build/bin/texstream-server"}) {
    if (::access(p.c_str(), X_OK) == 0) return p;
  }
  return {};
}

struct TinyScene {
  fs::path dir;
  std::vector<scene::TextureRecord> textures;
  std::map<uint32_t, std::vector<std::byte>> files;  // texture id → whole DDS file

  TinyScene() {
    dir = fs::temp_directory_path() / ("texstream-test-scene-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    // One RGBA8 64x32 texture and one BC1 32x32: both mip chains down to 1x1.
    textures = {{64, 32, full_mip_count(64, 32), static_cast<uint32_t>(TexelFormat::kRgba8)},
                {32, 32, full_mip_count(32, 32), static_cast<uint32_t>(TexelFormat::kBc1)}};
    scene::Manifest m;
    m.name = "stream-e2e";
    m.mesh_count = 0;
    m.texture_count = textures.size();
    EXPECT_TRUE(scene::write_manifest(dir, m).ok());
    EXPECT_TRUE(scene::write_meshes(dir, scene::MeshData{}).ok());
    EXPECT_TRUE(scene::write_texture_table(dir, textures).ok());
    const std::vector<uint32_t> colors(textures.size(), 0xff808080u);
    EXPECT_TRUE(scene::write_colormap(dir, colors).ok());
    for (uint32_t id = 0; id < textures.size(); ++id) {
      const auto& t = textures[id];
      const TexelFormat f = static_cast<TexelFormat>(t.format);
      const auto header = scene::make_dds_header(f, t.width, t.height, t.mip_count);
      std::vector<std::byte> bytes(header.begin(), header.end());
      const uint64_t total = scene::dds_file_bytes(f, t.width, t.height, t.mip_count);
      for (uint64_t i = bytes.size(); i < total; ++i)
        bytes.push_back(static_cast<std::byte>((i * 7 + id * 101) & 0xff));
      const fs::path path = scene::texture_path(dir, TextureId(id));
      fs::create_directories(path.parent_path());
      std::ofstream(path, std::ios::binary)
          .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
      files[id] = std::move(bytes);
    }
  }
  ~TinyScene() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }

  std::vector<std::byte> mip(uint32_t id, uint32_t level) const {
    const auto& t = textures[id];
    const TexelFormat f = static_cast<TexelFormat>(t.format);
    const uint64_t off = scene::dds_mip_offset(f, t.width, t.height, level);
    const uint64_t n = mip_bytes(f, t.width, t.height, level);
    const auto& file = files.at(id);
    return {file.begin() + static_cast<std::ptrdiff_t>(off), file.begin() + static_cast<std::ptrdiff_t>(off + n)};
  }
};

class CheckingSink : public stream::MipSink {
 public:
  CheckingSink(const TinyScene& s, stream::TextureStates& states) : scene_(s), states_(states) {}
  std::span<std::byte> reserve(TextureId, MipLevel, uint64_t bytes) override {
    buffer_.assign(bytes, std::byte{0});
    return buffer_;
  }
  void commit(TextureId t, MipLevel m, std::span<std::byte> data) override {
    const auto want = scene_.mip(t.value, m.value);
    EXPECT_TRUE(std::equal(data.begin(), data.end(), want.begin(), want.end()))
        << "texture " << t.value << " mip " << m.value << " differs from its bytes in the DDS file";
    EXPECT_TRUE(states_.on_committed(t, m));
    ++commits;
  }
  void reject(TextureId t, MipLevel m, std::span<std::byte>) override {
    ADD_FAILURE() << "rejected texture " << t.value << " mip " << m.value;
    states_.on_rejected(t, m);
  }
  void failed(TextureId t, MipLevel m, CompletionStatus s) override {
    ++failures;
    states_.on_failed(t, m, s);
    if (s != CompletionStatus::kUnfilled && s != CompletionStatus::kCancelled) {
      ADD_FAILURE() << "texture " << t.value << " mip " << m.value << ": " << to_string(s);
    }
  }
  int commits = 0;
  int failures = 0;

 private:
  const TinyScene& scene_;
  stream::TextureStates& states_;
  std::vector<std::byte> buffer_;
};

TEST(StreamRealServer, StreamsEveryMipOfATinySceneEndToEnd) {
  const fs::path server = find_server();
  // The server is a build dependency of this test (stream_tests.cmake), so its absence is a failure.
  ASSERT_FALSE(server.empty()) << "texstream-server not found (looked in " << TEXSTREAM_BIN_DIR
                               << ", build-server/bin, build/bin; or set TEXSTREAM_SERVER)";
  TinyScene scene;
  Config config;
  config.protocol.segment_name = "texstream-test-e2e-" + std::to_string(::getpid());
  config.protocol.staging_slot_count = 4;
  config.server.executable = server.string();
  config.server.worker_threads = 1;
  config.scene.dir = scene.dir.string();
  std::vector<TextureShape> shapes;
  for (const auto& t : scene.textures)
    shapes.push_back({t.width, t.height, t.mip_count, static_cast<TexelFormat>(t.format)});
  // The server reads its own configuration: pass what differs from the defaults as overrides.
  const std::vector<std::string> overrides{"protocol.staging_slot_count=4", "server.worker_threads=1",
                                           "server.log_level=warn"};
  auto started = stream::StreamClient::start(config, shapes, scene.dir, "", overrides, {});
  ASSERT_TRUE(started.ok()) << started.error().message;
  auto client = std::move(*started);

  stream::TextureStates states(shapes);
  CheckingSink sink(scene, states);
  const std::vector<stream::StreamCandidate> list{{TextureId(0), 0, 2}, {TextureId(1), 0, 1}};
  const auto deadline = std::chrono::steady_clock::now() + 60s;
  while (states.counts().final < 2 || states.counts().pending > 0) {
    ASSERT_LT(std::chrono::steady_clock::now(), deadline)
        << "not streamed in time: " << client->stats().completions_ok << " mips, server "
        << to_string(client->stats().server_state);
    client->begin_cycle();
    (void)states.run_cycle(list, 1 << 20, 0, client->sender());
    client->poll(sink, 8);
    std::this_thread::sleep_for(1ms);
  }
  const stream::StreamStats st = client->stats();
  // Texture 0 (64x32): levels 4..0; texture 1 (32x32): levels 3..0 — coarsest (4x4-ish) first.
  EXPECT_EQ(sink.commits, 5 + 4);
  EXPECT_EQ(st.completions_ok, 9u);
  EXPECT_EQ(st.protocol_errors, 0u);
  EXPECT_EQ(st.server_deaths, 0u);
  EXPECT_EQ(st.server_state, stream::StreamServerState::kRunning);
  EXPECT_EQ(states.view(TextureId(0)).resident, 0u);
  EXPECT_EQ(states.view(TextureId(1)).resident, 0u);
}

}  // namespace
}  // namespace texstream
