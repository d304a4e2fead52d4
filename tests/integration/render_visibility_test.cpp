// GPU visibility metadata on lavapipe (issue 5), through render::ViewRenderer (the renderer's own passes, no
// streaming) on scenes built in memory, and on a small generated city:
//   - per-mesh mip of a camera-facing plane equals the analytic level at three distances (±0 levels);
//   - grazing angles, zero derivatives, a plane through the near plane, an 8K-wide target: finite, in range,
//     no weight wrap;
//   - on a city: >= 99% of fragments within one level of textureQueryLod; weight > 0 set == id-buffer set
//     (tau = 0, no off-screen widening); the same view at (0,0,0) and (4e6,5e6,0) gives PSNR >= 60 dB;
//   - the window mode under Xvfb renders the asked frames and exits 0.
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>
#include "process_test_support.hpp"

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/render/frame/view_renderer.hpp"

namespace fs = std::filesystem;
using namespace texstream;
using namespace texstream::render;

namespace {

const fs::path kBin = TEXSTREAM_BIN_DIR;
using texstream::test::slurp;
int run(const std::string& cmd, const fs::path& log) { return texstream::test::run_logged(cmd, log); }
constexpr double kX = 392000.0, kY = 5820000.0, kZ = 40.0;  // map coordinates on purpose
constexpr uint32_t kTex = 512;                              // texture side: mip_max = 9
constexpr int kW = 480, kH = 270;
constexpr double kFov = 60.0;

double focal_px(int height) { return (height / 2.0) / std::tan(kFov * M_PI / 360.0); }

Config base_config(int width = kW, int height = kH) {
  Config c;
  c.render.width_px = width;
  c.render.height_px = height;
  c.render.fov_y_deg = kFov;
  c.render.offscreen_fov_y_deg = kFov;  // the wide pass adds nothing: only the viewport's fragments count
  c.render.validation = true;
  c.stream.tau = 0;
  return c;
}

// One quad of side `side` m, `distance` m north of the camera (which looks north), tilted by `tilt_deg` about
// the x axis (0: facing the camera). `uv_const`: every vertex has uv (0.5, 0.5) (zero derivatives).
SceneData plane_scene(double distance, double side, double tilt_deg, bool uv_const = false) {
  SceneData s;
  s.manifest.texture_format = TexelFormat::kRgba8;
  s.manifest.origin = {kX, kY, kZ};
  s.textures.push_back(scene::TextureRecord{kTex, kTex, 10, static_cast<uint32_t>(TexelFormat::kRgba8)});
  s.colormap.push_back(0xff808080u);
  const float h = static_cast<float>(side / 2);
  const double t = tilt_deg * M_PI / 180.0;
  // Rotate the quad's vertical edge towards the view direction: (0, 0, z) -> (0, z sin t, z cos t).
  auto v = [&](float x, float z, float u, float w) {
    scene::Vertex vert{};
    vert.pos[0] = x;
    vert.pos[1] = static_cast<float>(static_cast<double>(z) * std::sin(t));
    vert.pos[2] = static_cast<float>(static_cast<double>(z) * std::cos(t));
    vert.normal[1] = -1;
    vert.uv[0] = uv_const ? 0.5f : u;
    vert.uv[1] = uv_const ? 0.5f : w;
    return vert;
  };
  s.meshes.vertices = {v(-h, -h, 0, 1), v(h, -h, 1, 1), v(h, h, 1, 0), v(-h, h, 0, 0)};
  s.meshes.indices = {0, 1, 2, 0, 2, 3};
  scene::MeshRecord m{};
  m.origin[0] = kX;
  m.origin[1] = kY + distance;
  m.origin[2] = kZ;
  for (int a = 0; a < 3; ++a) {
    m.bounds_min[a] = -h;
    m.bounds_max[a] = h;
  }
  m.vertex_count = 4;
  m.index_count = 6;
  s.meshes.meshes.push_back(m);
  s.manifest.mesh_count = 1;
  s.manifest.texture_count = 1;
  return s;
}

const CameraPose kLookNorth{{kX, kY, kZ}, 0, 0};

// Camera-facing quads of side `side` m, all in the plane `distance` m north of the camera, the i-th shifted
// east by x_shift[i] m: quads with the same shift coincide (every fragment ties in depth).
SceneData coplanar_scene(double distance, double side, const std::vector<double>& x_shift) {
  SceneData s = plane_scene(distance, side, 0);
  const scene::MeshRecord first = s.meshes.meshes[0];
  s.meshes.meshes.clear();
  for (double dx : x_shift) {
    scene::MeshRecord m = first;  // same vertices and indices: bit-identical depths
    m.origin[0] += dx;
    s.meshes.meshes.push_back(m);
  }
  s.manifest.mesh_count = static_cast<uint32_t>(x_shift.size());
  return s;
}

std::set<uint32_t> weighted_set(const ViewResult& v) {
  std::set<uint32_t> out;
  for (const auto& e : v.entries)
    if (e.weight_fixed > 0) out.insert(e.mesh_id);
  return out;
}

std::set<uint32_t> id_buffer_set(const ViewResult& v) {
  std::set<uint32_t> out;
  for (size_t i = 0; i + 3 < v.rgba.size(); i += 4) {
    const int64_t id = decode_mesh_id(v.rgba[i], v.rgba[i + 1], v.rgba[i + 2]);
    if (id >= 0) out.insert(static_cast<uint32_t>(id));
  }
  return out;
}

ViewResult render_one(const Config& cfg, SceneData scene, const CameraPose& pose = kLookNorth) {
  auto vr = ViewRenderer::create(cfg, std::move(scene));
  EXPECT_TRUE(vr.ok()) << (vr.ok() ? "" : vr.error().message);
  if (!vr.ok()) return {};
  auto v = (*vr)->render(pose);
  EXPECT_TRUE(v.ok()) << (v.ok() ? "" : v.error().message);
  EXPECT_EQ((*vr)->validation_errors(), 0u);
  return v.ok() ? std::move(*v) : ViewResult{};
}

fs::path fresh_dir(const std::string& name) { return texstream::test::fresh_dir("texstream_vis_it_", name); }

}  // namespace

TEST(RenderVisibility, CameraFacingPlaneMipEqualsTheAnalyticLevel) {
  const double side = 10.0;
  for (double lod : {0.5, 1.5, 2.5, 4.25}) {
    // Texels per pixel = (kTex / side) * distance / focal: pick the distance that gives `lod`.
    const double distance = std::exp2(lod) * side * focal_px(kH) / kTex;
    const ViewResult v = render_one(base_config(), plane_scene(distance, side, 0));
    ASSERT_EQ(v.entries.size(), 1u) << "lod " << lod;
    const double mip = v.entries[0].mip_fixed / static_cast<double>(gpu::kMipFixedScale);
    EXPECT_NEAR(mip, lod, 0.02) << "distance " << distance;  // fixed point is 1/256 of a level
    EXPECT_EQ(std::floor(mip), std::floor(lod));             // the same level: ±0
    EXPECT_GT(v.entries[0].weight_fixed, 0u);
  }
}

TEST(RenderVisibility, GrazingPlaneIsWithinOneLevelAndFinite) {
  // A plane tilted 80 degrees (almost edge-on): the finest fragment lies at its near edge, where the footprint
  // is stretched along the view: with A_m = 16 the metadata may differ from the fronto-parallel level at the
  // same depth by at most the anisotropy it cannot absorb, and must stay in [0, M_max].
  const double side = 10.0, distance = 20.0;
  const ViewResult flat = render_one(base_config(), plane_scene(distance, side, 0));
  const ViewResult graze = render_one(base_config(), plane_scene(distance, side, 80));
  ASSERT_EQ(flat.entries.size(), 1u);
  ASSERT_EQ(graze.entries.size(), 1u);
  const double m_flat = flat.entries[0].mip_fixed / 256.0;
  const double m_graze = graze.entries[0].mip_fixed / 256.0;
  EXPECT_TRUE(std::isfinite(m_graze));
  EXPECT_LE(m_graze, 9.0);
  // The near edge is at distance - (side / 2) sin 80 from the camera: its fronto-parallel level is the bound.
  const double near_edge = distance - side / 2 * std::sin(80 * M_PI / 180);
  const double near_lod = std::log2(kTex / side * near_edge / focal_px(kH));
  EXPECT_NEAR(m_graze, near_lod, 1.0) << "flat " << m_flat;
}

TEST(RenderVisibility, ZeroDerivativesGiveMipZeroAndAFiniteWeight) {
  const ViewResult v = render_one(base_config(), plane_scene(20.0, 10.0, 0, /*uv_const=*/true));
  ASSERT_EQ(v.entries.size(), 1u);
  EXPECT_EQ(v.entries[0].mip_fixed, 0u);  // infinite magnification clamps to the finest level
  EXPECT_GT(v.entries[0].weight_fixed, 0u);
  EXPECT_LT(v.entries[0].weight_fixed, gpu::kWeightSaturate);
}

TEST(RenderVisibility, PlaneThroughTheNearPlaneIsFinite) {
  // Tilted 89 degrees and 1.2 m away: part of it lies closer than near_m = 1 and is clipped.
  const ViewResult v = render_one(base_config(), plane_scene(1.2, 10.0, 89));
  ASSERT_EQ(v.entries.size(), 1u);
  EXPECT_LE(v.entries[0].mip_fixed, 9u * gpu::kMipFixedScale);
  EXPECT_GT(v.entries[0].weight_fixed, 0u);
}

TEST(RenderVisibility, EightKWideTargetDoesNotWrapTheWeight) {
  // 8192 x 1024 with a plane filling the view: ~8.4 M fragments of W up to 17 would wrap a plain 32-bit sum
  // of 1/16 units at 15.8 M fragments of W = 17; the saturating sum must stay >= one unit per fragment.
  Config cfg = base_config(8192, 1024);
  cfg.render.debug_view = DebugView::kMeshId;
  const ViewResult v = render_one(cfg, plane_scene(2.0, 400.0, 0));
  ASSERT_EQ(v.entries.size(), 1u);
  uint64_t covered = 0;
  for (size_t i = 0; i + 3 < v.rgba.size(); i += 4)
    covered += decode_mesh_id(v.rgba[i], v.rgba[i + 1], v.rgba[i + 2]) == 0 ? 1 : 0;
  EXPECT_EQ(covered, 8192ull * 1024ull);
  const uint64_t floor_units = std::min<uint64_t>(covered * gpu::kWeightFixedScale, gpu::kWeightSaturate);
  EXPECT_GE(v.entries[0].weight_fixed, floor_units);
  EXPECT_LE(v.entries[0].mip_fixed, 9u * gpu::kMipFixedScale);
}

// Coplanar surfaces tie in depth, so both pass the shading pass's EQUAL test; only the pixel's owner (the
// pre-pass's first-drawn fragment) may count. Meshes 0 and 1 coincide, mesh 2 overlaps half of them: exactly
// two meshes are visible (one of 0/1, and 2), in the metadata as in the id buffer. Letting every fragment that
// passes EQUAL write metadata (the old rule) gives three.
TEST(RenderVisibility, CoplanarSurfacesCountOnlyTheirOwner) {
  Config cfg = base_config();
  cfg.render.debug_view = DebugView::kMeshId;
  const ViewResult v = render_one(cfg, coplanar_scene(20.0, 10.0, {0.0, 0.0, 5.0}));
  const std::set<uint32_t> meta = weighted_set(v), ids = id_buffer_set(v);
  EXPECT_EQ(meta, ids);
  EXPECT_EQ(ids.size(), 2u);
  EXPECT_EQ(meta.size(), 2u);
  EXPECT_EQ(ids.count(2), 1u);
  EXPECT_EQ(ids.count(0) + ids.count(1), 1u);
}

// Several fully coincident quads: the id buffer shows one of them, and that one alone has metadata (the owner
// rule decides the colour and the metadata together).
TEST(RenderVisibility, CoincidentMeshesTheShownOneIsTheCountedOne) {
  Config cfg = base_config();
  cfg.render.debug_view = DebugView::kMeshId;
  for (int copies : {2, 5}) {
    const ViewResult v = render_one(cfg, coplanar_scene(15.0, 8.0, std::vector<double>(copies, 0.0)));
    const std::set<uint32_t> meta = weighted_set(v), ids = id_buffer_set(v);
    EXPECT_EQ(ids.size(), 1u) << copies << " coincident quads";
    EXPECT_EQ(meta, ids) << copies << " coincident quads";
  }
}

// The wider off-screen FOV gives W = 1 per viewport pixel to meshes that lie outside the viewport (seed 000
// §3.2), at the level the viewport would need; a mesh straddling the viewport's edge is in the viewport and
// keeps exactly the main pass's metadata. Looking north at 960x540 with FOV 60, the viewport's edge runs at
// |x| = 1.026 y, the wide FOV's (75) at |x| = 1.364 y. Quads of 10 m facing the camera:
//   0: straight ahead, 40 m north;
//   1: across the viewport's left edge (x -36..-26 at 30 m: the edge is at -30.8);
//   2: outside the viewport, inside the wide FOV (x 43..53 at 40 m: 1.075 y .. 1.325 y).
TEST(RenderVisibility, OnlyMeshesOutsideTheViewportGetTheOffScreenWeight) {
  const double side = 10.0;
  SceneData scene = plane_scene(40.0, side, 0);
  scene::MeshRecord ahead = scene.meshes.meshes[0];
  ahead.bounds_min[1] = ahead.bounds_max[1] = 0.0f;   // the quads are flat: a box 10 m deep would reach the viewport
  scene::MeshRecord across = ahead, outside = ahead;  // the same vertices, moved
  across.origin[0] = kX - 31.0;
  across.origin[1] = kY + 30.0;
  outside.origin[0] = kX + 48.0;
  scene.meshes.meshes = {ahead, across, outside};
  scene.manifest.mesh_count = 3;
  auto by_mesh = [](const ViewResult& v) {
    std::map<uint32_t, gpu::CompactEntry> out;
    for (const auto& e : v.entries) out[e.mesh_id] = e;
    return out;
  };
  const int width = 960, height = 540;  // the wide pass at 240x135: the off-screen quad is ~22 of its pixels wide
  Config wide = base_config(width, height);
  wide.render.offscreen_fov_y_deg = 75.0;
  const auto narrow_meta =
      by_mesh(render_one(base_config(width, height), scene));  // wide FOV = viewport: no off-screen mesh
  const auto wide_meta = by_mesh(render_one(wide, scene));
  ASSERT_EQ(narrow_meta.size(), 2u);
  ASSERT_EQ(wide_meta.size(), 3u);
  for (uint32_t mesh : {0u, 1u}) {
    ASSERT_EQ(narrow_meta.count(mesh), 1u) << "mesh " << mesh;
    EXPECT_EQ(wide_meta.at(mesh).mip_fixed, narrow_meta.at(mesh).mip_fixed) << "mesh " << mesh;
    EXPECT_EQ(wide_meta.at(mesh).weight_fixed, narrow_meta.at(mesh).weight_fixed) << "mesh " << mesh;
  }
  // Mesh 2 is parallel to the image plane, so it projects to a square of side * f / 40 viewport pixels, f the
  // focal length in pixels, and needs the level log2(texels per pixel) there. The wide pass rasterizes it at
  // a quarter of the resolution (about 22 x 22 of its pixels): its edges decide up to ~10 % of the area.
  const gpu::CompactEntry& off = wide_meta.at(2);
  const double f = focal_px(height), pixels = std::pow(side * f / 40.0, 2.0);
  EXPECT_NEAR(off.weight_fixed / static_cast<double>(gpu::kWeightFixedScale), pixels, 0.15 * pixels);
  const double level = std::log2(kTex / side * 40.0 / f);
  EXPECT_NEAR(off.mip_fixed / static_cast<double>(gpu::kMipFixedScale), level, 0.5);
}

class RenderVisibilityCity : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fresh_dir("city");
    const int rc = run((kBin / "texstream-gen").string() + " --out " + (dir_ / "scene").string() +
                           " --textures 300 --seed 5 --threads 1",
                       dir_ / "gen.log");
    ASSERT_EQ(rc, 0) << slurp(dir_ / "gen.log");
    auto s = SceneData::load(dir_ / "scene");
    ASSERT_TRUE(s.ok()) << s.error().message;
    scene_ = new SceneData(std::move(*s));
    auto path = CameraPath::load(dir_ / "scene" / scene_->manifest.camera_path);
    ASSERT_TRUE(path.ok());
    for (int i = 0; i < 3; ++i) poses_.push_back(path->sample(path->duration_s() * (i + 0.5) / 3));
  }
  static void TearDownTestSuite() {
    delete scene_;
    scene_ = nullptr;
    fs::remove_all(dir_);
  }
  static inline fs::path dir_;
  static inline SceneData* scene_ = nullptr;
  static inline std::vector<CameraPose> poses_;
};

TEST_F(RenderVisibilityCity, LodWithinOneLevelOfTextureQueryLod) {
  ASSERT_NE(scene_, nullptr);
  ViewRendererOptions o;
  o.lod_probe = true;
  auto vr = ViewRenderer::create(base_config(), *scene_, o);
  ASSERT_TRUE(vr.ok()) << vr.error().message;
  uint64_t total = 0, within = 0;
  for (const auto& pose : poses_) {
    auto v = (*vr)->render(pose, {true, false, false});
    ASSERT_TRUE(v.ok()) << v.error().message;
    for (const auto& s : v->probe) {
      if (s.written == 0.0f) continue;
      ASSERT_TRUE(std::isfinite(s.computed));
      ++total;
      within += std::abs(std::clamp(s.computed, 0.0f, s.mip_max) - std::clamp(s.queried, 0.0f, s.mip_max)) <= 1.0f;
    }
  }
  ASSERT_GT(total, 10000u);
  EXPECT_GE(static_cast<double>(within) / static_cast<double>(total), 0.99);
  EXPECT_EQ((*vr)->validation_errors(), 0u);
}

TEST_F(RenderVisibilityCity, WeightedSetEqualsTheIdBufferSet) {
  ASSERT_NE(scene_, nullptr);
  Config cfg = base_config();
  cfg.render.debug_view = DebugView::kMeshId;
  auto vr = ViewRenderer::create(cfg, *scene_);
  ASSERT_TRUE(vr.ok()) << vr.error().message;
  int views_with_meshes = 0;
  for (const auto& pose : poses_) {
    auto v = (*vr)->render(pose);
    ASSERT_TRUE(v.ok()) << v.error().message;
    const std::set<uint32_t> meta = weighted_set(*v), ids = id_buffer_set(*v);
    EXPECT_EQ(meta, ids);
    // The compaction writes each mesh's texture id into its entry (the CPU merges by it).
    for (const auto& e : v->entries) {
      ASSERT_LT(e.mesh_id, scene_->meshes.meshes.size());
      EXPECT_EQ(e.texture_id, scene_->meshes.meshes[e.mesh_id].texture_id) << "mesh " << e.mesh_id;
    }
    if (ids.empty()) continue;  // a view of the small city's outskirts may see nothing
    ++views_with_meshes;
    // Occlusion matters: the broad phase submits more than is visible.
    EXPECT_GT(v->submitted, ids.size());
  }
  EXPECT_GE(views_with_meshes, 2);
}

TEST_F(RenderVisibilityCity, FarOffsetGivesTheSamePicture) {
  ASSERT_NE(scene_, nullptr);
  Config cfg = base_config();
  const auto& o = scene_->manifest.origin;
  const std::array<double, 3> to_zero{-o[0], -o[1], -o[2]};
  const std::array<double, 3> to_far{4.0e6 - o[0], 5.0e6 - o[1], -o[2]};
  auto shifted = [](CameraPose p, const std::array<double, 3>& by) {
    for (int a = 0; a < 3; ++a) p.position[a] += by[a];
    return p;
  };
  ViewRendererOptions zo, fo;
  zo.scene_offset = to_zero;
  fo.scene_offset = to_far;
  auto near_vr = ViewRenderer::create(cfg, *scene_, zo);
  auto far_vr = ViewRenderer::create(cfg, *scene_, fo);
  ASSERT_TRUE(near_vr.ok() && far_vr.ok());
  for (const auto& pose : poses_) {
    auto a = (*near_vr)->render(shifted(pose, to_zero));
    auto b = (*far_vr)->render(shifted(pose, to_far));
    ASSERT_TRUE(a.ok() && b.ok());
    ASSERT_EQ(a->rgba.size(), b->rgba.size());
    double se = 0;
    for (size_t i = 0; i < a->rgba.size(); ++i) {
      const double d = static_cast<double>(a->rgba[i]) - static_cast<double>(b->rgba[i]);
      se += d * d;
    }
    const double mse = se / static_cast<double>(a->rgba.size());
    const double psnr = mse == 0 ? 1e9 : 10 * std::log10(255.0 * 255.0 / mse);
    EXPECT_GE(psnr, 60.0);
  }
}

TEST(RenderWindow, RunsFramesUnderXvfbAndExitsZero) {
  // scripts/bootstrap.sh installs xvfb: its absence is a broken setup, not a reason to skip.
  ASSERT_EQ(std::system("command -v xvfb-run > /dev/null 2>&1"), 0) << "xvfb-run not installed (package xvfb)";
  const fs::path dir = fresh_dir("window");
  ASSERT_EQ(run((kBin / "texstream-gen").string() + " --out " + (dir / "scene").string() +
                    " --textures 100 --seed 9 --threads 1",
                dir / "gen.log"),
            0);
  const fs::path out = dir / "out";
  const std::string cmd = "xvfb-run -a -s '-screen 0 640x480x24' " + (kBin / "texstream-render").string() +
                          " --set scene.dir=" + (dir / "scene").string() +
                          " --set render.window=true --set render.validation=true --set render.frames=6"
                          " --set render.width_px=320 --set render.height_px=180 --set render.write_every_frames=0"
                          " --set render.output_dir=" +
                          out.string();
  const int rc = run(cmd, dir / "render.log");
  const std::string log = slurp(dir / "render.log");
  ASSERT_EQ(rc, 0) << log;
  const auto summary = nlohmann::json::parse(slurp(out / "summary.json"));
  EXPECT_EQ(summary["frames"].get<int>(), 6) << log;
  EXPECT_EQ(summary["validation_errors"].get<int>(), 0) << log;
  EXPECT_TRUE(fs::exists(out / "frames" / "frame_00005.png")) << log;  // the last frame is always written
  EXPECT_NE(log.find("latency"), std::string::npos) << log;            // the readout
  fs::remove_all(dir);
}
