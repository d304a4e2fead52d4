// The sparse cache in texstream-render (issue 6), with the real server, lavapipe and the validation layer.
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>
#include "process_test_support.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#define STB_IMAGE_IMPLEMENTATION
#define STBI_ONLY_PNG
#include <stb_image.h>

#include "texstream/common/camera_path.hpp"

namespace fs = std::filesystem;

namespace {

const fs::path kBin = TEXSTREAM_BIN_DIR;
using texstream::test::slurp;
int run(const std::string& cmd, const fs::path& log) { return texstream::test::run_logged(cmd, log); }

fs::path fresh_dir(const std::string& name) { return texstream::test::fresh_dir("texstream_cache_it_", name); }

fs::path make_scene(const fs::path& dir, const std::string& format, int textures) {
  const fs::path scene = dir / "scene";
  EXPECT_EQ(run((kBin / "texstream-gen").string() + " --out " + scene.string() + " --textures " +
                    std::to_string(textures) + " --seed 3 --threads 1 --format " + format,
                dir / "gen.log"),
            0)
      << slurp(dir / "gen.log");
  return scene;
}

std::string render_cmd(const fs::path& scene, const fs::path& out, const std::string& sets) {
  return (kBin / "texstream-render").string() + " --config " +
         (fs::path(TEXSTREAM_SOURCE_DIR) / "config/test.toml").string() + " --set scene.dir=" + scene.string() +
         " --set render.output_dir=" + out.string() + " " + sets;
}

// (texel format, cache.eviction)
class CacheThrash : public ::testing::TestWithParam<std::tuple<std::string, std::string>> {};

}  // namespace

// A budget of 4 MiB (64 pages; BC1: 1 MiB) against a fly-through that sees hundreds of textures: textures (lru) or
// layers (ring) are evicted for the budget every few frames, yet no frame ends with more bytes bound than the budget,
// and nothing is invalid.
TEST_P(CacheThrash, BoundPagesNeverExceedTheBudget) {
  const auto [format, eviction] = GetParam();
  const fs::path dir = fresh_dir("thrash_" + format + "_" + eviction);
  const fs::path scene = make_scene(dir, format, 600);
  const fs::path out = dir / "out";
  // BC1 takes an eighth of RGBA8's bytes: with 4 MiB the lru cache holds the whole path's BC1 working set.
  // mixed (BC1, BC3, RGBA8 5:2:1, each in its own plane) takes about twice BC1's.
  const uint64_t budget = format == "bc1" ? 1ull << 20 : format == "mixed" ? 2ull << 20 : 4ull << 20;
  const int rc =
      run(render_cmd(scene, out,
                     "--set cache.memory_bytes=" + std::to_string(budget) + " --set cache.eviction=" + eviction +
                         " --set render.frames=40 --set render.write_every_frames=0"),
          dir / "render.log");
  const std::string log = slurp(dir / "render.log");
  ASSERT_EQ(rc, 0) << log;
  const auto cache = nlohmann::json::parse(slurp(out / "cache.json"));
  const auto summary = nlohmann::json::parse(slurp(out / "summary.json"));
  EXPECT_EQ(summary["validation_errors"].get<int>(), 0) << log;
  EXPECT_EQ(cache["frames"].get<uint64_t>(), 40u);
  EXPECT_EQ(cache["planes"].size(), format == "mixed" ? 3u : 1u) << "one cache image per texel format";
  EXPECT_EQ(cache["budget_exceeded_frames"].get<uint64_t>(), 0u);
  EXPECT_LE(cache["max_bound_bytes"].get<uint64_t>(), budget);
  EXPECT_LE(cache["allocated_bytes"].get<uint64_t>(), budget);
  EXPECT_GT(cache["max_bound_bytes"].get<uint64_t>(), budget / 2) << "the budget was never under pressure";
  EXPECT_GT(cache["evictions"].get<uint64_t>(), 0u) << "no thrashing: the test does not test";
  if (eviction == "ring") {
    EXPECT_GT(cache["budget_evicted_layers"].get<uint64_t>(), 0u);
  } else {
    // The memory was full when the first texture went: the budget, not the address space, was the limit.
    EXPECT_GE(cache["fill_at_first_eviction"].get<double>(), 0.9);
    EXPECT_EQ(cache["layers_recycled"].get<uint64_t>(), 0u);
  }
  EXPECT_GT(cache["pages_unbound"].get<uint64_t>(), 0u);
  EXPECT_GT(cache["pages_shared"].get<uint64_t>(), 0u) << "small regions should share pages";
  EXPECT_GT(summary["mips_streamed"].get<int>(), 0);
  // One vkQueueBindSparse per frame at most.
  EXPECT_LE(cache["bind_calls"].get<uint64_t>(), 40u);
  fs::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Formats, CacheThrash,
                         ::testing::Combine(::testing::Values("rgba8", "bc1", "mixed"),
                                            ::testing::Values("lru", "ring")),
                         [](const auto& p) { return std::get<0>(p.param) + "_" + std::get<1>(p.param); });

// lru fills the free pages with the copies that fit before it evicts for one that does not: with budgets of
// 4 MiB plus 1..3 pages (RGBA8: a 512² level 0 takes 16 pages), nothing goes while pages are free. Evicting in
// commit order left those pages free at the first eviction (0.985, 0.970, 0.955 of the budget).
TEST(CacheBudget, FreePagesAreFilledBeforeAnythingIsEvicted) {
  const fs::path dir = fresh_dir("fill_first");
  const fs::path scene = make_scene(dir, "rgba8", 600);
  for (uint64_t pages = 1; pages <= 3; ++pages) {
    const uint64_t budget = (4ull << 20) + pages * 65536;
    const fs::path out = dir / ("out" + std::to_string(pages));
    const int rc = run(render_cmd(scene, out,
                                  "--set cache.memory_bytes=" + std::to_string(budget) +
                                      " --set render.frames=40 --set render.write_every_frames=0"),
                       dir / "render.log");
    ASSERT_EQ(rc, 0) << slurp(dir / "render.log");
    const auto cache = nlohmann::json::parse(slurp(out / "cache.json"));
    ASSERT_EQ(cache["page_bytes"].get<uint64_t>(), 65536u) << "the budgets assume 64 KiB pages";
    ASSERT_GT(cache["evictions"].get<uint64_t>(), 0u) << "the budget was never short";
    EXPECT_GE(cache["fill_at_first_eviction"].get<double>(), 0.99) << budget << " B";
  }
  fs::remove_all(dir);
}

// Close to the facades, then a cut to a high view of the same street with a 1 MiB budget, far below the high
// view's working set: textures still in view after the cut hold finer levels than they now want, and with
// nothing unused left to evict the cache drops those levels (TextureCache::trim_one) instead of only refusing
// copies; with validation on, the budget never exceeded, and the run completes.
TEST(CacheBudget, AViewThatZoomsOutDropsLevelsItNoLongerWants) {
  const fs::path dir = fresh_dir("trim");
  const fs::path scene = make_scene(dir, "bc1", 600);
  std::ifstream in(scene / "camera_path.txt");
  std::string line;
  double t = 0, x = 0, y = 0, z = 0, yaw = 0, pitch = 0;
  while (std::getline(in, line) && (line.empty() || line[0] == '#')) {
  }
  std::istringstream(line) >> t >> x >> y >> z >> yaw >> pitch;
  std::ofstream path(dir / "zoom_out.txt");
  path << std::fixed << "0 " << x << " " << y << " 6 " << yaw << " 0\n3 " << x << " " << y << " 6 " << yaw << " 0\n3 "
       << x << " " << y << " 400 " << yaw << " -45\n8 " << x << " " << y << " 400 " << yaw << " -45\n";
  path.close();
  const fs::path out = dir / "out";
  const int rc =
      run(render_cmd(scene, out,
                     "--set cache.memory_bytes=1048576 --set render.camera_path=" + (dir / "zoom_out.txt").string() +
                         " --set render.frames=0 --set render.width_px=640 --set render.height_px=360"
                         " --set render.lockstep=true --set controller.mode=none"
                         " --set render.write_every_frames=0 --set render.validation=true"),
          dir / "render.log");
  const std::string log = slurp(dir / "render.log");
  ASSERT_EQ(rc, 0) << log;
  const auto cache = nlohmann::json::parse(slurp(out / "cache.json"));
  const auto summary = nlohmann::json::parse(slurp(out / "summary.json"));
  EXPECT_EQ(summary["validation_errors"].get<int>(), 0) << log;
  EXPECT_EQ(cache["budget_exceeded_frames"].get<uint64_t>(), 0u);
  EXPECT_GT(cache["space_refusals"].get<uint64_t>(), 0u) << "the budget was meant to be below the view's";
  EXPECT_GT(cache["trimmed_levels"].get<uint64_t>(), 0u);
  fs::remove_all(dir);
}

TEST(CacheBudget, TooSmallForOneLayerTextureIsANamedError) {
  const fs::path dir = fresh_dir("small");
  const fs::path scene = make_scene(dir, "rgba8", 20);
  // 1 MiB = 16 pages; a 512 texture needs 16 + 4 + 8 x 1 = 28 pages with every level.
  const int rc =
      run(render_cmd(scene, dir / "out", "--set cache.memory_bytes=1048576 --set render.frames=2"), dir / "render.log");
  const std::string log = slurp(dir / "render.log");
  EXPECT_NE(rc, 0);
  EXPECT_NE(log.find("cache.memory_bytes"), std::string::npos) << log;
  fs::remove_all(dir);
}

// The texture table (gpu::TextureGpu, 48 B, host-visible) holds a slot per texture drawn in the frame or cached,
// not one per scene texture (docs/design/host_memory.md, item 3): after a fly-through of a 12,000-texture city that
// draws a few thousand textures at a time, the table is its first 4096 entries, under half of a per-texture table,
// and slots of textures that left the view were freed for others. A per-texture table again fails the bound.
TEST(CacheTable, TheTextureTableFollowsTheTexturesInUseNotTheScene) {
  const fs::path dir = fresh_dir("table");
  constexpr uint64_t kTextures = 12000, kEntryBytes = 48;
  const fs::path scene = make_scene(dir, "bc1", static_cast<int>(kTextures));
  const fs::path out = dir / "out";
  const int rc = run(render_cmd(scene, out, "--set render.frames=40 --set stream.fade_ms=200"), dir / "render.log");
  const std::string log = slurp(dir / "render.log");
  ASSERT_EQ(rc, 0) << log;
  const auto cache = nlohmann::json::parse(slurp(out / "cache.json"));
  const auto summary = nlohmann::json::parse(slurp(out / "summary.json"));
  EXPECT_EQ(summary["validation_errors"].get<int>(), 0) << log;
  EXPECT_GT(summary["mips_streamed"].get<int>(), 0);
  const auto slots = cache["texture_table_slots"].get<uint64_t>();
  const auto peak = cache["texture_slots_peak"].get<uint64_t>();
  EXPECT_EQ(cache["texture_table_bytes"].get<uint64_t>(), slots * kEntryBytes);
  EXPECT_GT(peak, 0u);
  EXPECT_LE(peak, slots);
  // Doubling from 4096: never more than twice the slots held at once.
  EXPECT_LE(slots, std::max<uint64_t>(4096, 2 * peak));
  EXPECT_LT(peak, kTextures / 2) << "the path was meant to see a part of the city at a time";
  EXPECT_LT(cache["texture_table_bytes"].get<uint64_t>(), kTextures * kEntryBytes / 2);
  EXPECT_GT(cache["texture_slots_released"].get<uint64_t>(), 0u) << "no texture left the view: nothing reused";
  fs::remove_all(dir);
}

namespace {
std::vector<unsigned char> load_rgb(const fs::path& f, int& w, int& h) {
  int n = 0;
  unsigned char* p = stbi_load(f.string().c_str(), &w, &h, &n, 3);
  if (!p) return {};
  std::vector<unsigned char> v(p, p + static_cast<size_t>(w) * h * 3);
  stbi_image_free(p);
  return v;
}
}  // namespace

// A static view streamed for N frames against the same view after 3N frames: converged (PSNR >= 45 dB), and
// the converged frame differs from frame 0 (the colormap only), so the comparison is not vacuous.
TEST(CacheConvergence, StaticViewConvergesToTheLongRun) {
  const fs::path dir = fresh_dir("converge");
  const fs::path scene = make_scene(dir, "rgba8", 300);
  auto path = texstream::CameraPath::load(scene / "camera_path.txt");
  ASSERT_TRUE(path.ok());
  const auto p = path->keys().front().pose;
  {
    std::ofstream f(dir / "still.txt");
    f.precision(17);
    f << "0 " << p.position[0] << " " << p.position[1] << " " << p.position[2] << " " << p.yaw_deg << " " << p.pitch_deg
      << "\n";
  }
  const std::string common = "--set render.camera_path=" + (dir / "still.txt").string() +
                             " --set cache.memory_bytes=268435456 --set render.validation=false";
  ASSERT_EQ(run(render_cmd(scene, dir / "a", common + " --set render.frames=16 --set render.write_every_frames=15"),
                dir / "a.log"),
            0)
      << slurp(dir / "a.log");
  ASSERT_EQ(run(render_cmd(scene, dir / "b", common + " --set render.frames=48"), dir / "b.log"), 0)
      << slurp(dir / "b.log");
  int w0, h0, w1, h1, w2, h2;
  const auto first = load_rgb(dir / "a/frames/frame_00000.png", w0, h0);
  const auto a = load_rgb(dir / "a/frames/frame_00015.png", w1, h1);
  const auto b = load_rgb(dir / "b/frames/frame_00047.png", w2, h2);
  ASSERT_FALSE(a.empty() || b.empty() || first.empty());
  ASSERT_EQ(a.size(), b.size());
  auto mse = [](const std::vector<unsigned char>& x, const std::vector<unsigned char>& y) {
    double s = 0;
    for (size_t i = 0; i < x.size(); ++i) s += (double(x[i]) - double(y[i])) * (double(x[i]) - double(y[i]));
    return s / double(x.size());
  };
  const double m = mse(a, b);
  const double psnr = m == 0 ? 100.0 : 10.0 * std::log10(255.0 * 255.0 / m);
  EXPECT_GE(psnr, 45.0) << "MSE " << m;
  EXPECT_GT(mse(first, b), 1.0) << "frame 0 already equals the converged frame: nothing was streamed";
  fs::remove_all(dir);
}
