// texstream-gen --ground pages (issue 28): the blocks' grounds leave the meshes and become one page file whose
// finest level holds each block's ground where the block lies, painted as the ground painter paints it; the scene's
// ids stay dense, the other textures are those of the meshes' scene, the bytes do not depend on the thread count,
// and the placement and texel size follow the options.
#include <gtest/gtest.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>

#include "city_ground.hpp"
#include "city_layout.hpp"
#include "scene_generator.hpp"
#include "texstream/common/mesh_index.hpp"
#include "texstream/common/page_file.hpp"
#include "texstream/common/scene_format.hpp"
#include "texture_painter.hpp"

namespace fs = std::filesystem;
using namespace texstream;

namespace {

std::vector<uint8_t> read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// The finest level of an RGBA8 page file, read back page by page through its index.
class FinestLevel {
 public:
  explicit FinestLevel(const fs::path& path) : bytes_(read_all(path)) {
    auto f = pages::PageFile::open(path);
    EXPECT_TRUE(f.ok()) << f.error().message;
    if (f.ok()) file_ = std::move(*f);
  }
  const pages::PageGeometry& geometry() const { return file_.geometry(); }
  // Texel (u, v) of the finest level: u east, v north.
  uint32_t at(uint32_t u, uint32_t v) const {
    const pages::PageGeometry& g = file_.geometry();
    const auto e = file_.entry({g.levels - 1, u / g.page_texels, v / g.page_texels});
    EXPECT_TRUE(e.has_value()) << "no page over texel " << u << ", " << v;
    if (!e) return 0;
    const uint64_t i =
        uint64_t{v % g.page_texels + g.border_texels} * g.stored_side() + u % g.page_texels + g.border_texels;
    uint32_t t;
    std::memcpy(&t, bytes_.data() + e->offset + 4 * i, 4);
    return t;
  }

 private:
  std::vector<uint8_t> bytes_;
  pages::PageFile file_;
};

class CityGroundTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() / ("texstream_ground_test_" + std::to_string(::getpid()) + "_" +
                                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(root_);
    fs::create_directories(root_);
  }
  void TearDown() override { fs::remove_all(root_); }

  gen::GeneratorOptions options(const std::string& name, uint64_t n, uint64_t seed, TexelFormat format,
                                gen::GroundMode ground, double texel_m = 0) const {
    gen::GeneratorOptions o;
    o.out = root_ / name;
    o.texture_count = n;
    o.seed = seed;
    o.format = format;
    o.threads = 2;
    o.ground = ground;
    o.ground_texel_m = texel_m;
    return o;
  }
  gen::GeneratorStats generate(const gen::GeneratorOptions& o) {
    auto r = gen::generate_scene(o);
    EXPECT_TRUE(r.ok()) << r.error().message;
    return r.ok() ? *r : gen::GeneratorStats{};
  }

  fs::path root_;
};

uint64_t hash_file(const fs::path& p) {
  const auto b = read_all(p);
  return XXH64(b.data(), b.size(), 0);
}

}  // namespace

TEST_F(CityGroundTest, PagesSceneHoldsTheBlockGroundsInOnePageFile) {
  constexpr uint64_t kN = 300, kSeed = 3;
  const auto opt = options("s", kN, kSeed, TexelFormat::kRgba8, gen::GroundMode::kPages);
  const auto stats = generate(opt);
  const fs::path dir = opt.out;
  const gen::CityLayout layout = gen::generate_layout(kSeed, kN);
  std::vector<uint32_t> kept, grounds;  // layout indices
  for (uint32_t k = 0; k < layout.surfaces.size(); ++k)
    (layout.surfaces[k].kind == gen::SurfaceKind::kGround ? grounds : kept).push_back(k);
  ASSERT_GE(grounds.size(), 2u);
  EXPECT_EQ(stats.ground_surfaces, grounds.size());

  // Dense ids over what remains: mesh k is layout surface kept[k] with texture k.
  auto manifest = scene::read_manifest(dir);
  ASSERT_TRUE(manifest.ok()) << manifest.error().message;
  EXPECT_EQ(manifest->mesh_count, kept.size());
  EXPECT_EQ(manifest->texture_count, kept.size());
  auto meshes = scene::read_meshes(dir);
  ASSERT_TRUE(meshes.ok()) << meshes.error().message;
  auto table = scene::read_texture_table(dir);
  ASSERT_TRUE(table.ok()) << table.error().message;
  ASSERT_TRUE(scene::read_colormap(dir, kept.size()).ok());
  ASSERT_EQ(meshes->meshes.size(), kept.size());
  ASSERT_EQ(table->size(), kept.size());
  for (size_t k = 0; k < kept.size(); ++k) {
    const scene::MeshRecord& m = meshes->meshes[k];
    const gen::Surface& s = layout.surfaces[kept[k]];
    EXPECT_EQ(m.texture_id, k);
    for (int a = 0; a < 3; ++a) EXPECT_EQ(m.origin[a], opt.origin[static_cast<size_t>(a)] + s.corner[a]) << k;
    EXPECT_EQ((*table)[k].width, s.width_px);
    EXPECT_EQ((*table)[k].height, s.height_px);
    EXPECT_EQ(m.vertex_count, 4u) << "mesh " << k << " is a ground's 4x4 grid";
    EXPECT_TRUE(fs::exists(scene::texture_path(dir, TextureId{static_cast<uint32_t>(k)})));
  }
  EXPECT_FALSE(fs::exists(scene::texture_path(dir, TextureId{static_cast<uint32_t>(kept.size())})));

  // The ground: placed at the blocks, at their height, covering every former ground quad.
  ASSERT_TRUE(manifest->ground.has_value());
  const scene::GroundPages& g = *manifest->ground;
  EXPECT_EQ(g.pages, "ground.tspages");
  EXPECT_DOUBLE_EQ(g.metres_per_texel, gen::kGroundTexelM);
  const FinestLevel level(dir / g.pages);
  ASSERT_EQ(level.geometry().format, TexelFormat::kRgba8);
  const double extent_x = level.geometry().width * g.metres_per_texel,
               extent_y = level.geometry().height * g.metres_per_texel;
  const uint32_t block_px = 480;  // 120 m at 0.25 m
  for (uint32_t k : grounds) {
    const gen::Surface& s = layout.surfaces[k];
    const double x0 = opt.origin[0] + s.corner[0], y0 = opt.origin[1] + s.corner[1];
    EXPECT_EQ(g.origin[2], opt.origin[2] + s.corner[2]) << "the ground lies where the ground meshes did";
    EXPECT_GE(x0, g.origin[0]);
    EXPECT_GE(y0, g.origin[1]);
    EXPECT_LE(x0 + static_cast<double>(s.width_m), g.origin[0] + extent_x);
    EXPECT_LE(y0 + static_cast<double>(s.height_m), g.origin[1] + extent_y);

    // The block's texels are the ground painter's at the image's scale (its image row 0 is north, v grows north).
    gen::Surface scaled = s;
    scaled.width_px = scaled.height_px = static_cast<uint16_t>(block_px);
    std::vector<uint32_t> want(size_t{block_px} * block_px);
    gen::paint_texture(kSeed, k, scaled, want);
    const auto u0 = static_cast<uint32_t>(std::lround((x0 - g.origin[0]) / g.metres_per_texel));
    const auto v0 = static_cast<uint32_t>(std::lround((y0 - g.origin[1]) / g.metres_per_texel));
    size_t differ = 0;
    for (uint32_t y = 0; y < block_px; ++y)
      for (uint32_t x = 0; x < block_px; ++x)
        differ += level.at(u0 + x, v0 + block_px - 1 - y) != want[size_t{y} * block_px + x];
    EXPECT_EQ(differ, 0u) << "block ground of surface " << k;
  }
  // Nothing left black or transparent between the blocks.
  size_t dark = 0;
  for (uint32_t v = 0; v < level.geometry().height; v += 7)
    for (uint32_t u = 0; u < level.geometry().width; u += 7) {
      const uint32_t t = level.at(u, v);
      dark += (t >> 24) != 255 || ((t & 0xff) + ((t >> 8) & 0xff) + ((t >> 16) & 0xff)) < 30;
    }
  EXPECT_EQ(dark, 0u);
  // The scene's bounds include its ground.
  EXPECT_LE(manifest->bounds_min[0], g.origin[0]);
  EXPECT_GE(manifest->bounds_max[1], g.origin[1] + extent_y);
}

TEST_F(CityGroundTest, PagesLeaveTheOtherTexturesAsTheMeshesSceneHasThem) {
  const auto meshes = options("m", 200, 5, TexelFormat::kBc1, gen::GroundMode::kMeshes);
  const auto pages = options("p", 200, 5, TexelFormat::kBc1, gen::GroundMode::kPages, 1.0);
  generate(meshes);
  generate(pages);
  auto m = scene::read_manifest(meshes.out);
  ASSERT_TRUE(m.ok());
  EXPECT_FALSE(m->ground.has_value());
  EXPECT_EQ(m->texture_count, 200u);
  EXPECT_FALSE(fs::exists(meshes.out / gen::kGroundPagesFile));
  auto p = scene::read_manifest(pages.out);
  ASSERT_TRUE(p.ok());
  ASSERT_TRUE(p->ground.has_value());
  EXPECT_EQ(p->ground->metres_per_texel, 1.0);
  auto f = pages::PageFile::open(pages.out / gen::kGroundPagesFile);
  ASSERT_TRUE(f.ok()) << f.error().message;
  EXPECT_EQ(f->geometry().format, TexelFormat::kBc1);

  const gen::CityLayout layout = gen::generate_layout(5, 200);
  uint32_t id = 0;
  for (uint32_t k = 0; k < layout.surfaces.size(); ++k) {
    if (layout.surfaces[k].kind == gen::SurfaceKind::kGround) continue;
    ASSERT_EQ(hash_file(scene::texture_path(pages.out, TextureId{id})),
              hash_file(scene::texture_path(meshes.out, TextureId{k})))
        << "texture " << id << " of the pages scene, " << k << " of the meshes scene";
    ++id;
  }
  EXPECT_EQ(id, p->texture_count);
  // The fly-through follows the blocks, which both scenes share; the broad phase's tree is that of the meshes left.
  EXPECT_EQ(hash_file(pages.out / "camera_path.txt"), hash_file(meshes.out / "camera_path.txt"));
  auto index = scene::map_mesh_index(pages.out, p->mesh_count);
  EXPECT_TRUE(index.ok()) << index.error().message;
}

TEST_F(CityGroundTest, PageFileBytesDoNotDependOnThreads) {
  auto a = options("a", 200, 9, TexelFormat::kBc1, gen::GroundMode::kPages, 0.5);
  auto b = options("b", 200, 9, TexelFormat::kBc1, gen::GroundMode::kPages, 0.5);
  a.threads = 1;
  generate(a);
  generate(b);
  const uint64_t ha = hash_file(a.out / gen::kGroundPagesFile);
  EXPECT_NE(ha, XXH64(nullptr, 0, 0));
  EXPECT_EQ(ha, hash_file(b.out / gen::kGroundPagesFile));
  EXPECT_EQ(hash_file(a.out / "scene.json"), hash_file(b.out / "scene.json"));
  EXPECT_EQ(hash_file(a.out / "meshes.bin"), hash_file(b.out / "meshes.bin"));
}

TEST_F(CityGroundTest, FormatFollowsTheScene) {
  auto o = options("x", 10, 1, TexelFormat::kBc1, gen::GroundMode::kPages);
  EXPECT_EQ(gen::ground_format(o), TexelFormat::kBc1);
  o.format = TexelFormat::kRgba8;
  EXPECT_EQ(gen::ground_format(o), TexelFormat::kRgba8);
  o.format = TexelFormat::kBc3;
  EXPECT_EQ(gen::ground_format(o), TexelFormat::kBc1);
  o.format = TexelFormat::kRgba8;
  o.mixed_formats = true;
  EXPECT_EQ(gen::ground_format(o), TexelFormat::kBc1);
}

TEST_F(CityGroundTest, RefusesACityOfOneGroundAlone) {
  auto r = gen::generate_scene(options("one", 1, 1, TexelFormat::kBc1, gen::GroundMode::kPages));
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("--ground pages"), std::string::npos) << r.error().message;
}

TEST(CityGroundPlan, TexelSizeIsWholeTexelsPerBlockAndTheDefaultStaysWithin16K) {
  // Two blocks 81 cells apart: 81 x 480 texels at 0.25 m would pass 16384 a side.
  gen::CityLayout city;
  for (int32_t i : {-40, 40}) {
    gen::Surface s{};
    s.kind = gen::SurfaceKind::kGround;
    s.corner[0] = (i - 0.5) * gen::kBlockPitchM;
    s.corner[1] = (3 - 0.5) * gen::kBlockPitchM;
    s.width_m = s.height_m = static_cast<float>(gen::kBlockPitchM);
    city.surfaces.push_back(s);
  }
  auto plan = gen::plan_ground(city, 0);
  ASSERT_TRUE(plan.ok());
  EXPECT_EQ(plan->cells_x, 81u);
  EXPECT_EQ(plan->cells_y, 1u);
  EXPECT_EQ(plan->i0, -40);
  EXPECT_EQ(plan->j0, 3);
  EXPECT_EQ(plan->block_px, 16384u / 81);
  EXPECT_LE(plan->width(), gen::kGroundAutoMaxSide);
  EXPECT_DOUBLE_EQ(plan->metres_per_texel, gen::kBlockPitchM / (16384 / 81));
  EXPECT_DOUBLE_EQ(plan->west_m(), -40.5 * gen::kBlockPitchM);

  auto asked = gen::plan_ground(city, 0.26);  // 461.5 texels a block: 462
  ASSERT_TRUE(asked.ok());
  EXPECT_EQ(asked->block_px, 462u);
  EXPECT_DOUBLE_EQ(asked->metres_per_texel, gen::kBlockPitchM / 462);
  EXPECT_FALSE(gen::plan_ground(city, 0.001).ok());  // 120000 texels a block
  auto too_big = gen::plan_ground(city, 0.03);       // 4000 x 81 texels a side
  ASSERT_FALSE(too_big.ok());
  EXPECT_NE(too_big.error().message.find("--ground-texel-m"), std::string::npos);
}

TEST_F(CityGroundTest, ForceReplacesAPreviousGround) {
  auto o = options("f", 60, 2, TexelFormat::kBc1, gen::GroundMode::kPages, 2.0);
  generate(o);
  ASSERT_TRUE(fs::exists(o.out / gen::kGroundPagesFile));
  o.ground = gen::GroundMode::kMeshes;
  o.force = true;
  generate(o);
  EXPECT_FALSE(fs::exists(o.out / gen::kGroundPagesFile)) << "a meshes scene with a stale ground beside it";
  auto m = scene::read_manifest(o.out);
  ASSERT_TRUE(m.ok());
  EXPECT_FALSE(m->ground.has_value());
}
