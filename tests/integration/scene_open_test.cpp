// Start-up that follows the view (issue 6), on lavapipe through render::ViewRenderer (the renderer's own
// passes): a generated city opened (files mapped, tree mapped from mesh_index.bin, geometry uploaded as meshes
// first enter the frustum) draws exactly what the loaded city draws, pixel for pixel and entry for entry,
// view after view; without mesh_index.bin it builds the tree, keeps it, and still draws the same; a corrupt
// mesh is reported, naming meshes.bin and the mesh, by the frame that first needs it; dropping the meshes that
// cover no pixel centre (BroadPhase::drop_unsampled) changes no pixel and no metadata entry.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <vector>

#include "process_test_support.hpp"
#include "texstream/common/camera_path.hpp"
#include "texstream/common/config.hpp"
#include "texstream/render/frame/view_renderer.hpp"

namespace fs = std::filesystem;
using namespace texstream;
using namespace texstream::render;

namespace {

const fs::path kBin = TEXSTREAM_BIN_DIR;

Config view_config(const std::string& debug_view) {
  Config c;
  c.render.width_px = 320;
  c.render.height_px = 180;
  c.render.validation = true;
  c.render.debug_view = choice_from_name<DebugView>(debug_view).value();
  return c;
}

std::vector<std::array<uint32_t, 3>> sorted_entries(const ViewResult& v) {
  std::vector<std::array<uint32_t, 3>> out;
  for (const auto& e : v.entries) out.push_back({e.mesh_id, e.mip_fixed, e.weight_fixed});
  std::sort(out.begin(), out.end());
  return out;
}

class SceneOpen : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = texstream::test::fresh_dir("texstream_scene_open_it_", "city");
    const int rc = texstream::test::run_logged((kBin / "texstream-gen").string() + " --out " +
                                                   (dir_ / "scene").string() + " --textures 400 --seed 11 --threads 1",
                                               dir_ / "gen.log");
    ASSERT_EQ(rc, 0) << texstream::test::slurp(dir_ / "gen.log");
    auto path = CameraPath::load(dir_ / "scene" / "camera_path.txt");
    ASSERT_TRUE(path.ok());
    // Views along the path: later ones bring meshes the earlier ones did not upload.
    for (int i = 0; i < 5; ++i) poses_.push_back(path->sample(path->duration_s() * (i + 0.5) / 5));
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  // Every pose rendered by one ViewRenderer over `scene`, in path order or backwards (other meshes are then
  // already resident when a view is drawn: the upload history must not show), results in path order.
  static std::vector<ViewResult> render_all(const Config& cfg, SceneData scene, bool backwards = false,
                                            bool staged = false, bool drop_unsampled = true) {
    return render_poses(cfg, std::move(scene), poses_, backwards, staged, drop_unsampled);
  }
  static std::vector<ViewResult> render_poses(const Config& cfg, SceneData scene, const std::vector<CameraPose>& poses,
                                              bool backwards = false, bool staged = false, bool drop_unsampled = true) {
    std::vector<ViewResult> out;
    ViewRendererOptions o;
    o.stage_geometry = staged;
    o.drop_unsampled = drop_unsampled;
    auto vr = ViewRenderer::create(cfg, std::move(scene), o);
    EXPECT_TRUE(vr.ok()) << (vr.ok() ? "" : vr.error().message);
    if (!vr.ok()) return out;
    for (size_t k = 0; k < poses.size(); ++k) {
      auto v = (*vr)->render(poses[backwards ? poses.size() - 1 - k : k]);
      EXPECT_TRUE(v.ok()) << (v.ok() ? "" : v.error().message);
      if (v.ok()) out.push_back(std::move(*v));
    }
    if (backwards) std::reverse(out.begin(), out.end());
    EXPECT_EQ((*vr)->validation_errors(), 0u);
    return out;
  }

  // Same pictures and metadata; `same_draws`: also the same draw lists (false when one side dropped meshes).
  static void expect_same(const std::vector<ViewResult>& a, const std::vector<ViewResult>& b, const char* what,
                          bool same_draws = true, size_t views = poses_.size()) {
    ASSERT_EQ(a.size(), views) << what;
    ASSERT_EQ(b.size(), views) << what;
    for (size_t i = 0; i < a.size(); ++i) {
      EXPECT_EQ(a[i].submitted, b[i].submitted) << what << ", view " << i;
      if (same_draws) {
        EXPECT_EQ(a[i].main_meshes, b[i].main_meshes) << what << ", view " << i;
      }
      EXPECT_TRUE(a[i].rgba == b[i].rgba) << what << ", view " << i << ": pixels differ";
      // Workgroups claim list slots in the order they run: compare the entries as sets.
      EXPECT_EQ(sorted_entries(a[i]), sorted_entries(b[i])) << what << ", view " << i << ": compacted metadata differs";
    }
  }

  static inline fs::path dir_;
  static inline std::vector<CameraPose> poses_;
};

TEST_F(SceneOpen, OpenedSceneDrawsExactlyWhatTheLoadedSceneDraws) {
  const fs::path scene = dir_ / "scene";
  ASSERT_TRUE(fs::exists(scene / "mesh_index.bin")) << "texstream-gen writes the tree";
  for (const char* view : {"none", "mesh_id"}) {
    auto loaded = SceneData::load(scene);
    ASSERT_TRUE(loaded.ok()) << loaded.error().message;
    auto opened = SceneData::open(scene);
    ASSERT_TRUE(opened.ok()) << opened.error().message;
    const auto a = render_all(view_config(view), std::move(*loaded));
    SceneData backwards = *opened, staged = *opened;
    const auto b = render_all(view_config(view), std::move(*opened));
    expect_same(a, b, view);
    expect_same(a, render_all(view_config(view), std::move(backwards), /*backwards=*/true), "backwards");
    // The discrete-GPU path: meshes copied through staging in the frame's command buffer.
    expect_same(a, render_all(view_config(view), std::move(staged), false, /*staged=*/true), "staged");
    uint64_t drawn = 0;
    for (const auto& v : a) drawn += v.main_meshes;
    EXPECT_GT(drawn, 0u) << "the views must see the city";
  }
}

TEST_F(SceneOpen, DroppingUnsampledMeshesChangesNoPixelAndNoMetadata) {
  // At 64x36 most of the city is a fraction of a pixel: many meshes are dropped, and each must have been one
  // without a fragment. Both the colour and the id view, the main and the wide pass (metadata).
  uint64_t dropped = 0;
  for (const auto& [w, h] : {std::pair{320, 180}, std::pair{64, 36}}) {
    for (const char* view : {"none", "mesh_id"}) {
      Config cfg = view_config(view);
      cfg.render.width_px = w;
      cfg.render.height_px = h;
      auto s = SceneData::open(dir_ / "scene");
      ASSERT_TRUE(s.ok());
      SceneData copy = *s;
      const auto all = render_all(cfg, std::move(*s), false, false, /*drop_unsampled=*/false);
      const auto kept = render_all(cfg, std::move(copy));
      expect_same(all, kept, view, /*same_draws=*/false);
      for (size_t i = 0; i < all.size() && i < kept.size(); ++i) {
        EXPECT_EQ(all[i].unsampled, 0u);
        EXPECT_LE(kept[i].main_meshes, all[i].main_meshes);
        dropped += kept[i].unsampled;
      }
    }
  }
  EXPECT_GT(dropped, 100u) << "the test must drop meshes to show anything";
}

TEST_F(SceneOpen, WithoutTheIndexTheTreeIsBuiltKeptAndTheSame) {
  const fs::path copy = dir_ / "no_index";
  fs::remove_all(copy);
  fs::copy(dir_ / "scene", copy, fs::copy_options::recursive);
  fs::remove(copy / "mesh_index.bin");
  auto loaded = SceneData::load(copy);
  ASSERT_TRUE(loaded.ok());
  const auto a = render_all(view_config("mesh_id"), std::move(*loaded));
  auto opened = SceneData::open(copy);
  ASSERT_TRUE(opened.ok()) << opened.error().message;
  const auto b = render_all(view_config("mesh_id"), std::move(*opened));
  expect_same(a, b, "built here");
  EXPECT_TRUE(fs::exists(copy / "mesh_index.bin")) << "the tree is kept for the next start";
  auto reopened = SceneData::open(copy);
  ASSERT_TRUE(reopened.ok());
  expect_same(a, render_all(view_config("mesh_id"), std::move(*reopened)), "kept");
}

TEST_F(SceneOpen, CorruptMeshIsReportedByTheFrameThatNeedsIt) {
  // A mesh the first view draws, found with the id view.
  auto loaded = SceneData::load(dir_ / "scene");
  ASSERT_TRUE(loaded.ok());
  const auto views = render_all(view_config("mesh_id"), std::move(*loaded));
  ASSERT_FALSE(views.empty());
  std::set<uint32_t> ids;
  for (size_t i = 0; i + 3 < views[0].rgba.size(); i += 4) {
    const int64_t id = decode_mesh_id(views[0].rgba[i], views[0].rgba[i + 1], views[0].rgba[i + 2]);
    if (id >= 0) ids.insert(static_cast<uint32_t>(id));
  }
  ASSERT_FALSE(ids.empty()) << "the first view sees no mesh";
  const uint32_t victim = *ids.begin();

  const fs::path copy = dir_ / "corrupt";
  fs::remove_all(copy);
  fs::copy(dir_ / "scene", copy, fs::copy_options::recursive);
  {
    // Its first index now points past its own vertices.
    auto mapped = scene::map_meshes(copy);
    ASSERT_TRUE(mapped.ok());
    const uint64_t at = sizeof(scene::MeshFileHeader) + mapped->meshes.size() * sizeof(scene::MeshRecord) +
                        mapped->vertices.size() * sizeof(scene::Vertex) +
                        uint64_t{mapped->meshes[victim].first_index} * sizeof(uint32_t);
    const uint32_t bad = mapped->meshes[victim].vertex_count + 7;
    std::fstream f(copy / "meshes.bin", std::ios::binary | std::ios::in | std::ios::out);
    f.seekp(static_cast<std::streamoff>(at));
    f.write(reinterpret_cast<const char*>(&bad), sizeof bad);
  }
  EXPECT_FALSE(SceneData::load(copy).ok()) << "the reading path checks every mesh";
  auto opened = SceneData::open(copy);
  ASSERT_TRUE(opened.ok()) << "opening checks headers only: " << opened.error().message;
  auto vr = ViewRenderer::create(view_config("none"), std::move(*opened));
  ASSERT_TRUE(vr.ok()) << vr.error().message;
  auto v = (*vr)->render(poses_[0]);
  ASSERT_FALSE(v.ok()) << "a frame drew a corrupt mesh";
  const std::string needle = "meshes.bin: mesh " + std::to_string(victim) + ": index 0";
  EXPECT_NE(v.error().message.find(needle), std::string::npos) << v.error().message;
}

}  // namespace
