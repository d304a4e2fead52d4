// Page requests (RequestKind::kLoadPage, issue 28) served by a Server in this process over a real segment,
// from page files baked here with texstream_tile_lib: every stored page of an RGBA8 and a BC1 file comes back
// exactly as the file stores it (PageFile's index names the bytes) with its kind, file, level, x, y echoed,
// read by the dispatcher and local workers, or from a slow origin by the remote-fetch workers;
// every bad request (file index, level, x/y outside the quadtree, a page not stored, a scene without
// "ground") is answered with a failure status and the server goes on serving; a page file that scene.json
// names but that is missing or damaged stops the server at start, naming the file. And end to end: the
// StreamClient takes every page from the real server and accepts each answer under its own checks.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <thread>
#include <tuple>
#include <vector>

#include "../support/patience.hpp"
#include "page_baker.hpp"
#include "server_harness.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/checksum.hpp"
#include "texstream/server/storage/posix_storage.hpp"
#include "texstream/server/storage/slow_storage.hpp"
#include "texstream/stream/stream_client.hpp"

namespace fs = std::filesystem;

namespace texstream::test {
namespace {

std::vector<std::byte> file_bytes(const fs::path& p) {
  std::vector<std::byte> b(fs::file_size(p));
  std::ifstream(p, std::ios::binary).read(reinterpret_cast<char*>(b.data()), static_cast<std::streamsize>(b.size()));
  return b;
}

struct Answer {
  CompletionRecord record{};
  std::vector<std::byte> payload;
};
using PageKey = std::tuple<uint32_t, uint32_t, uint32_t, uint32_t>;  // file, level, x, y

class ServerPagesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("texstream-pages-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    // One texture, never asked for: the server needs a texture table; these tests ask only for pages.
    const scene::TextureRecord table[1] = {{16, 16, full_mip_count(16, 16), uint32_t(TexelFormat::kRgba8)}};
    ASSERT_TRUE(scene::write_texture_table(dir_, table).ok());
  }
  void TearDown() override {
    harness_.reset();
    fs::remove_all(dir_);
  }

  // Bakes a painted ground of 300x200 into <scene>/ground.tspages and names it in scene.json.
  void bake_ground(TexelFormat format, uint32_t page_texels) {
    auto ground = tile::make_painted_ground(300, 200, 0.5, 7);
    tile::BakeOptions opt;
    opt.format = format;
    opt.page_texels = page_texels;
    opt.threads = 1;
    ASSERT_TRUE(tile::bake_pages(*ground, opt, dir_ / "ground.tspages").ok());
    write_manifest(true);
  }
  void write_manifest(bool ground) {
    scene::Manifest m;
    m.name = "pages";
    m.texture_count = 1;
    m.texture_format = TexelFormat::kRgba8;
    if (ground) m.ground = scene::GroundPages{"ground.tspages", {0, 0, 0}, 0.5};
    ASSERT_TRUE(scene::write_manifest(dir_, m).ok());
  }
  void start(server::Storage* storage = nullptr) {
    std::string error;
    harness_ = ServerHarness::start(dir_, ServerConfig{}, storage ? *storage : storage_, error);
    ASSERT_NE(harness_, nullptr) << error;
  }

  // Pushes every page of `asked` in one generation, then collects one answer for each.
  std::map<PageKey, Answer> ask(const std::vector<std::pair<uint32_t, pages::PageId>>& asked) {
    ++generation_;
    size_t pushed = 0;
    std::map<PageKey, Answer> answers;
    const auto deadline = std::chrono::steady_clock::now() + kHangAfter;
    while (answers.size() < asked.size() && std::chrono::steady_clock::now() < deadline) {
      while (pushed < asked.size() &&
             harness_->push_page(asked[pushed].first, asked[pushed].second, generation_, 1.0f + float(pushed))) {
        ++pushed;
      }
      harness_->ring();
      const uint32_t n = harness_->poll([&](const CompletionRecord& c, std::span<const std::byte> payload) {
        EXPECT_EQ(c.request_kind, static_cast<uint32_t>(RequestKind::kLoadPage));
        EXPECT_EQ(c.generation, generation_);
        Answer& a = answers[{c.texture_id, c.mip_level, c.page_x, c.page_y}];
        EXPECT_EQ(a.record.status, 0u) << "two answers for one page";
        a.record = c;
        a.payload.assign(payload.begin(), payload.end());
      });
      if (n == 0) std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
    EXPECT_EQ(answers.size(), asked.size());
    return answers;
  }

  // Every stored page, asked in one batch, equals the file's bytes at its index entry.
  void expect_every_page_as_stored() {
    auto file = pages::PageFile::open(dir_ / "ground.tspages");
    ASSERT_TRUE(file.ok()) << file.error().message;
    const pages::PageGeometry& g = file->geometry();
    const std::vector<std::byte> whole = file_bytes(dir_ / "ground.tspages");
    std::vector<std::pair<uint32_t, pages::PageId>> asked;
    for (uint64_t s = 0; s < g.page_slots(); ++s) {
      if (file->stored(g.page_of_slot(s))) asked.push_back({0, g.page_of_slot(s)});
    }
    ASSERT_EQ(asked.size(), file->stored_pages());
    const auto answers = ask(asked);
    for (const auto& [f, p] : asked) {
      const auto it = answers.find({f, p.level, p.x, p.y});
      ASSERT_NE(it, answers.end()) << "level " << p.level << " page " << p.x << "," << p.y;
      const CompletionRecord& c = it->second.record;
      ASSERT_EQ(c.status, static_cast<uint32_t>(CompletionStatus::kOk)) << to_string(CompletionStatus(c.status));
      const pages::PageIndexEntry e = *file->entry(p);
      EXPECT_EQ(c.byte_size, e.bytes);
      EXPECT_EQ(c.format, static_cast<uint32_t>(g.format));
      EXPECT_EQ(c.width, g.stored_side());
      EXPECT_EQ(c.height, g.stored_side());
      const std::vector<std::byte>& got = it->second.payload;
      ASSERT_EQ(got.size(), e.bytes);
      EXPECT_TRUE(std::equal(got.begin(), got.end(), whole.begin() + static_cast<ptrdiff_t>(e.offset)))
          << "level " << p.level << " page " << p.x << "," << p.y;
      EXPECT_EQ(c.checksum, payload_checksum(got.data(), got.size()));
    }
    EXPECT_EQ(harness_->server().stats().pages_ok.load(), asked.size());
  }

  fs::path dir_;
  server::PosixStorage storage_;
  std::unique_ptr<ServerHarness> harness_;
  uint64_t generation_ = 0;
};

TEST_F(ServerPagesTest, ServesEveryStoredRgba8PageAsTheFileStoresIt) {
  bake_ground(TexelFormat::kRgba8, 64);
  start();
  expect_every_page_as_stored();
}

TEST_F(ServerPagesTest, ServesEveryStoredBc1PageAsTheFileStoresIt) {
  bake_ground(TexelFormat::kBc1, 32);
  start();
  expect_every_page_as_stored();
}

TEST_F(ServerPagesTest, FromASlowOriginTheRemoteFetchWorkersServeThem) {
  bake_ground(TexelFormat::kBc1, 32);
  server::SlowStorage slow(storage_, server::SlowStorageParams{.latency_ms = 1});  // remote(): never inline
  start(&slow);
  expect_every_page_as_stored();
  EXPECT_GE(harness_->server().remote_fetches(), 1u);
}

TEST_F(ServerPagesTest, BadRequestsAreAnsweredNotFoundAndTheServerGoesOn) {
  bake_ground(TexelFormat::kRgba8, 64);  // 300x200 in 64-texel pages: 4 levels, the square 512 texels wide
  start();
  const std::vector<std::pair<uint32_t, pages::PageId>> bad = {
      {1, {0, 0, 0}},            // no page file 1
      {0xffffffffu, {0, 0, 0}},  // nor any other
      {0, {4, 0, 0}},            // past the finest level
      {0, {31, 0, 0}},          {0xffffffffu, {0xffffffffu, 0xffffffffu, 0xffffffffu}},
      {0, {0, 1, 0}},                            // level 0 has one page
      {0, {2, 4, 0}},                            // level 2 has 4 x 4
      {0, {1, 0, 0xffffffffu}}, {0, {3, 7, 7}},  // inside the quadtree, outside the image: not stored
  };
  for (const auto& [key, a] : ask(bad)) {
    EXPECT_EQ(a.record.status, static_cast<uint32_t>(CompletionStatus::kNotFound))
        << "file " << std::get<0>(key) << " level " << std::get<1>(key);
    EXPECT_EQ(a.record.slot, kNoSlot);
  }
  // Still serving.
  const auto good = ask({{0, {0, 0, 0}}, {0, {3, 4, 3}}});
  for (const auto& [key, a] : good) EXPECT_EQ(a.record.status, static_cast<uint32_t>(CompletionStatus::kOk));
  EXPECT_EQ(harness_->server().stats().pages_ok.load(), 2u);
}

TEST_F(ServerPagesTest, SceneWithoutGroundAnswersNotFound) {
  write_manifest(false);
  start();
  for (const auto& [key, a] : ask({{0, {0, 0, 0}}})) {
    EXPECT_EQ(a.record.status, static_cast<uint32_t>(CompletionStatus::kNotFound));
  }
}

TEST_F(ServerPagesTest, SceneWithoutSceneJsonAnswersNotFound) {
  start();  // only the texture table: a bare origin's fetched table looks like this
  for (const auto& [key, a] : ask({{0, {0, 0, 0}}})) {
    EXPECT_EQ(a.record.status, static_cast<uint32_t>(CompletionStatus::kNotFound));
  }
}

TEST_F(ServerPagesTest, AMissingOrDamagedGroundStopsTheServerAtStartNamingTheFile) {
  write_manifest(true);  // names ground.tspages, which is not there
  std::string error;
  auto h = ServerHarness::start(dir_, ServerConfig{}, storage_, error);
  EXPECT_EQ(h, nullptr);
  EXPECT_NE(error.find("ground.tspages"), std::string::npos) << error;

  bake_ground(TexelFormat::kRgba8, 64);
  fs::resize_file(dir_ / "ground.tspages", 100);  // inside the index
  error.clear();
  h = ServerHarness::start(dir_, ServerConfig{}, storage_, error);
  EXPECT_EQ(h, nullptr);
  EXPECT_NE(error.find("ground.tspages"), std::string::npos) << error;
}

// The renderer's side as it will run: StreamClient (validating against its own PageFile) and a PageSink.
class CollectingPageSink : public stream::PageSink {
 public:
  std::span<std::byte> reserve_page(uint32_t, pages::PageId, uint64_t bytes) override {
    buffer.resize(bytes);
    return buffer;
  }
  void commit_page(uint32_t file, pages::PageId page, std::span<std::byte> data) override {
    committed[{file, page.level, page.x, page.y}].assign(data.begin(), data.end());
  }
  void page_failed(uint32_t file, pages::PageId page, CompletionStatus status) override {
    ADD_FAILURE() << "page file " << file << " level " << page.level << " page " << page.x << "," << page.y << ": "
                  << to_string(status);
  }
  std::vector<std::byte> buffer;
  std::map<PageKey, std::vector<std::byte>> committed;
};

class NoMipSink : public stream::MipSink {
 public:
  std::span<std::byte> reserve(TextureId, MipLevel, uint64_t) override { return {}; }
  void commit(TextureId, MipLevel, std::span<std::byte>) override {}
  void reject(TextureId, MipLevel, std::span<std::byte>) override {}
  void failed(TextureId, MipLevel, CompletionStatus) override {}
};

TEST_F(ServerPagesTest, TheStreamClientTakesEveryPageFromTheServer) {
  bake_ground(TexelFormat::kRgba8, 64);
  Config config;
  config.protocol.segment_name = "texstream-pages-client-" + std::to_string(::getpid());
  config.protocol.staging_slot_count = 8;
  config.protocol.staging_slot_bytes = 64 << 10;  // a 72x72 RGBA8 page is 20,736 bytes
  config.cache.layer_extent_px = 64;              // validate(): the largest cached mip must fit a slot
  config.stream.max_requests_in_flight = 8;
  stream::StreamClientOptions options;
  options.spawn_server = false;
  auto client = stream::StreamClient::start(config, {{16, 16, full_mip_count(16, 16), TexelFormat::kRgba8}}, dir_, "",
                                            {}, options);
  ASSERT_TRUE(client.ok()) << client.error().message;
  auto server = server::Server::create((*client)->segment(), dir_, ServerConfig{}, storage_);
  ASSERT_TRUE(server.ok()) << server.error().message;
  std::atomic<bool> stop{false};
  std::thread thread([&] { (*server)->run(stop); });

  auto file = pages::PageFile::open(dir_ / "ground.tspages");
  ASSERT_TRUE(file.ok()) << file.error().message;
  const auto shared = std::make_shared<const pages::PageFile>(std::move(file).value());
  CollectingPageSink sink;
  NoMipSink mips;
  (*client)->set_page_files({shared}, &sink);
  const pages::PageGeometry& g = shared->geometry();
  std::vector<pages::PageId> wanted;
  for (uint64_t s = 0; s < g.page_slots(); ++s) {
    if (shared->stored(g.page_of_slot(s))) wanted.push_back(g.page_of_slot(s));
  }
  (*client)->begin_cycle();
  const auto deadline = std::chrono::steady_clock::now() + kHangAfter;
  while (sink.committed.size() < wanted.size() && std::chrono::steady_clock::now() < deadline) {
    for (const pages::PageId& p : wanted) {
      if (sink.committed.count({0, p.level, p.x, p.y}) || (*client)->page_in_flight(0, p)) continue;
      if ((*client)->try_request_page(0, p, 1.0f) != stream::RequestOutcome::kSent) break;
    }
    (*client)->poll(mips, 16);
    (*client)->wait_for_completions(std::chrono::milliseconds(5));
  }
  stop = true;
  Doorbell((*client)->segment()).wake_all();
  thread.join();
  ASSERT_EQ(sink.committed.size(), wanted.size());
  const std::vector<std::byte> whole = file_bytes(dir_ / "ground.tspages");
  for (const pages::PageId& p : wanted) {
    const std::vector<std::byte>& got = sink.committed[{0, p.level, p.x, p.y}];
    const pages::PageIndexEntry e = *shared->entry(p);
    ASSERT_EQ(got.size(), e.bytes);
    EXPECT_TRUE(std::equal(got.begin(), got.end(), whole.begin() + static_cast<ptrdiff_t>(e.offset)));
  }
  const stream::StreamStats st = (*client)->stats();
  EXPECT_EQ(st.pages_ok, wanted.size());
  EXPECT_EQ(st.pages_failed, 0u);
  EXPECT_EQ(st.protocol_errors, 0u);
}

}  // namespace
}  // namespace texstream::test
