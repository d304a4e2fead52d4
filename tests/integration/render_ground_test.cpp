// The ground as one huge texture in pages (issue 28), end to end on lavapipe with validation on: a generated city
// whose ground is a page file (texstream-gen --ground pages), drawn by texstream-render through its page cache,
// frame table and needbuffer, fed by texstream-server one page at a time.
// - Seams: with every page each frame wants resident (render.load_wanted_before_drawing), every frame equals the
//   same ground drawn from one ordinary mipmapped texture (pages.reference) within kMaxSeamDiff per channel, at
//   page borders too (ground.frag samples bordered pages bilinearly, two levels trilinearly).
// - Streaming: in lock-step real time the needbuffer asks for pages, they arrive and are drawn; nothing fails.
#include <gtest/gtest.h>
#include <stb_image_write.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "process_test_support.hpp"
#include "texstream/render/measure/image_metrics.hpp"
#include "texstream/render/measure/reference_frames.hpp"

namespace fs = std::filesystem;

namespace {

const fs::path kBin = TEXSTREAM_BIN_DIR;
using texstream::test::slurp;

constexpr uint32_t kWidth = 320, kHeight = 180;
constexpr int kMaxSeamDiff = 2;  // of 255, RGBA8 pages (issue 28: seams_max_abs_diff <= 2)
constexpr int kFrames = 12;
// A page cache of 30 RGBA8 frames with only the root locked: each frame's pages fit, the path's do not (the
// run evicts; measured: 66 evictions over the whole path), so what is drawn must not depend on what left.
constexpr const char* kSmallPageCache = " --set pages.locked_levels=1 --set pages.memory_bytes=2219520";

std::string render_cmd(const fs::path& dir, const std::string& run, const std::string& sets) {
  return (kBin / "texstream-render").string() + " --set scene.dir=" + (dir / "scene").string() +
         " --set render.output_dir=" + (dir / run).string() + " --set render.width_px=" + std::to_string(kWidth) +
         " --set render.height_px=" + std::to_string(kHeight) + " --set render.frames=" + std::to_string(kFrames) +
         " --set render.frame_time_ms=4000 --set render.lockstep=true --set render.write_every_frames=1" +
         " --set controller.mode=none --set stream.colormap_blend=false --set render.validation=true" + sets;
}

nlohmann::json run_render(const fs::path& dir, const std::string& run, const std::string& sets) {
  const fs::path log = dir / (run + ".log");
  EXPECT_EQ(texstream::test::run_logged(render_cmd(dir, run, sets), log), 0) << slurp(log);
  return nlohmann::json::parse(slurp(dir / run / "summary.json"), nullptr, false);
}

class RenderGround : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = texstream::test::fresh_dir("texstream_render_it_", "ground");
    generated_ = texstream::test::run_logged((kBin / "texstream-gen").string() + " --out " + (dir_ / "scene").string() +
                                                 " --textures 300 --seed 11 --threads 2 --format rgba8 --ground pages",
                                             dir_ / "gen.log") == 0;
  }
  void SetUp() override { ASSERT_TRUE(generated_) << slurp(dir_ / "gen.log"); }
  static fs::path dir_;
  static bool generated_;
};
fs::path RenderGround::dir_;
bool RenderGround::generated_ = false;

// The largest channel difference of run `actual_run` against `expected_run` over every frame; a frame above
// kMaxSeamDiff fails the test with its difference (x32) written beside the runs.
int max_diff(const fs::path& dir, const std::string& actual_run, const std::string& expected_run) {
  auto expected = texstream::render::ReferenceFrames::open(dir / expected_run, kWidth, kHeight);
  auto actual = texstream::render::ReferenceFrames::open(dir / actual_run, kWidth, kHeight);
  EXPECT_TRUE(expected.ok() && actual.ok());
  if (!expected.ok() || !actual.ok()) return 255;
  int worst = 0;
  for (int i = 0; i < kFrames; ++i) {
    auto e = expected->frame(static_cast<uint64_t>(i));
    auto a = actual->frame(static_cast<uint64_t>(i));
    EXPECT_TRUE(e.ok() && a.ok()) << "frame " << i;
    if (!e.ok() || !a.ok()) return 255;
    const auto* pa = reinterpret_cast<const unsigned char*>(a->pixels.data());
    const auto* pe = reinterpret_cast<const unsigned char*>(e->pixels.data());
    std::vector<unsigned char> diff(size_t{kWidth} * kHeight * 4, 255);
    int frame_worst = 0;
    for (size_t k = 0; k < diff.size(); ++k) {
      if (k % 4 == 3) continue;
      const int d = std::abs(int{pa[k]} - int{pe[k]});
      frame_worst = std::max(frame_worst, d);
      diff[k] = static_cast<unsigned char>(std::min(255, d * 32));
    }
    worst = std::max(worst, frame_worst);
    if (frame_worst > kMaxSeamDiff) {
      const fs::path d = dir / (actual_run + "_frame_" + std::to_string(i) + "_diff_x32.png");
      stbi_write_png(d.c_str(), kWidth, kHeight, 4, diff.data(), kWidth * 4);
      ADD_FAILURE() << actual_run << " frame " << i << ": max |pages - reference| = " << frame_worst << " (at most "
                    << kMaxSeamDiff << ")\n  diff x32: " << d;
    }
  }
  return worst;
}

}  // namespace

TEST_F(RenderGround, PagesDrawTheGroundAsOneMipmappedTextureDoesWithoutSeams) {
  const std::string wanted = " --set render.load_wanted_before_drawing=true";
  const auto pages = run_render(dir_, "pages", wanted);
  const auto reference = run_render(dir_, "reference", wanted + " --set pages.reference=true");
  const auto small = run_render(dir_, "small", wanted + kSmallPageCache);
  ASSERT_TRUE(pages.is_object() && reference.is_object() && small.is_object());
  for (const auto* run : {&pages, &small}) {
    EXPECT_EQ((*run)["validation_errors"].get<int>(), 0);
    EXPECT_EQ((*run)["protocol_errors"].get<int>(), 0);
    ASSERT_TRUE(run->contains("ground_pages")) << run->dump();
    EXPECT_GT((*run)["ground_pages"]["uploaded"].get<int>(), 0);
    EXPECT_EQ((*run)["ground_pages"]["failed"].get<int>(), 0);
  }
  EXPECT_GT(small["ground_pages"]["evictions"].get<int>(), 0) << "the small page cache was meant to evict";
  const int worst = max_diff(dir_, "pages", "reference");
  const int worst_small = max_diff(dir_, "small", "reference");
  uint64_t ground_pixels = 0;
  // The ground is in view and drawn at the levels it wants: the page-level view of the same run.
  run_render(dir_, "levels", wanted + " --set render.debug_view=page_level");
  auto levels = texstream::render::ReferenceFrames::open(dir_ / "levels", kWidth, kHeight);
  ASSERT_TRUE(levels.ok());
  auto f = levels->frame(0);
  ASSERT_TRUE(f.ok());
  const auto* p = reinterpret_cast<const unsigned char*>(f->pixels.data());
  for (size_t k = 0; k < size_t{kWidth} * kHeight; ++k) {
    // Page levels are drawn as (level + 1) x 16 in red (shown) and green (wanted), blue 0 (meshes are pure
    // blue, the sky has blue); shown = wanted when every wanted page is loaded.
    if (p[4 * k + 2] == 0) {
      ++ground_pixels;
      EXPECT_EQ(p[4 * k], p[4 * k + 1]) << "pixel " << k << ": the wanted level is not the one shown";
      if (p[4 * k] != p[4 * k + 1]) break;
    }
  }
  EXPECT_GT(ground_pixels, uint64_t{kWidth} * kHeight / 20) << "the ground covers too little of frame 0";
  std::printf(
      "ground through pages vs one mipmapped texture: %d frames, max abs diff %d (%d with a small page cache that "
      "evicted %d pages), %llu ground pixels in frame 0\n",
      kFrames, worst, worst_small, small["ground_pages"]["evictions"].get<int>(),
      static_cast<unsigned long long>(ground_pixels));
}

TEST_F(RenderGround, TheNeedbufferAsksForPagesAndTheyArriveInRealTime) {
  const auto run = run_render(dir_, "streamed", " --set pages.per_frame=8");
  ASSERT_TRUE(run.is_object());
  EXPECT_EQ(run["validation_errors"].get<int>(), 0);
  EXPECT_EQ(run["protocol_errors"].get<int>(), 0);
  ASSERT_TRUE(run.contains("ground_pages"));
  const auto& g = run["ground_pages"];
  EXPECT_GT(g["requested"].get<int>(), 0);
  // Lock-step: each frame takes every answer to the previous one's requests; only the last frame's can be left.
  EXPECT_GE(g["uploaded"].get<int>(), g["requested"].get<int>() - 8) << g.dump();
  EXPECT_EQ(g["failed"].get<int>(), 0);
  EXPECT_LE(g["requested"].get<int>(), 8 * kFrames) << "pages.per_frame bounds the requests";
  EXPECT_GT(g["needs_last_frame"].get<int>(), 0);
  // Without the ground: the same scene, pages.enabled = false, has no ground section.
  const auto off = run_render(dir_, "off", " --set pages.enabled=false");
  ASSERT_TRUE(off.is_object());
  EXPECT_FALSE(off.contains("ground_pages"));
}
