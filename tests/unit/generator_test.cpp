// texstream-gen's engine: determinism (seed, thread count), file consistency (DDS headers vs the texture table,
// mip chain sizes, colormap = 1x1 mip), texture extents and content (not flat), exact texture counts.
#include <gtest/gtest.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>

#include "city_layout.hpp"
#include "colour.hpp"
#include "mip_chain.hpp"
#include "scene_generator.hpp"
#include "texstream/common/camera_path.hpp"
#include "texstream/common/scene_format.hpp"

namespace fs = std::filesystem;
using namespace texstream;

namespace {

std::vector<uint8_t> read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// XXH64 over every file's relative path and contents, in sorted path order.
uint64_t hash_tree(const fs::path& root) {
  std::vector<fs::path> files;
  for (const auto& e : fs::recursive_directory_iterator(root))
    if (e.is_regular_file()) files.push_back(fs::relative(e.path(), root));
  std::sort(files.begin(), files.end());
  XXH64_state_t* st = XXH64_createState();
  XXH64_reset(st, 0);
  for (const auto& f : files) {
    const std::string name = f.string();
    XXH64_update(st, name.data(), name.size() + 1);
    const auto bytes = read_all(root / f);
    XXH64_update(st, bytes.data(), bytes.size());
  }
  const uint64_t h = XXH64_digest(st);
  XXH64_freeState(st);
  return h;
}

// Texel (0, 0) of a BC1 block as 8-bit RGB (the DXT1 palette rules; endpoints expanded from 565).
std::array<int, 3> decode_bc1_texel0(const uint8_t* b) {
  const int c0 = b[0] | b[1] << 8, c1 = b[2] | b[3] << 8;
  const auto expand = [](int c) {
    const int r = (c >> 11) & 31, g = (c >> 5) & 63, bl = c & 31;
    return std::array<int, 3>{r << 3 | r >> 2, g << 2 | g >> 4, bl << 3 | bl >> 2};
  };
  const auto e0 = expand(c0), e1 = expand(c1);
  const int index = b[4] & 3;
  std::array<int, 3> out{};
  for (size_t ch = 0; ch < 3; ++ch) {
    switch (index) {
      case 0:
        out[ch] = e0[ch];
        break;
      case 1:
        out[ch] = e1[ch];
        break;
      case 2:
        out[ch] = c0 > c1 ? (2 * e0[ch] + e1[ch]) / 3 : (e0[ch] + e1[ch]) / 2;
        break;
      default:
        out[ch] = c0 > c1 ? (e0[ch] + 2 * e1[ch]) / 3 : 0;
        break;
    }
  }
  return out;
}

class GeneratorTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() / ("texstream_gen_test_" + std::to_string(::getpid()) + "_" +
                                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(root_);
    fs::create_directories(root_);
  }
  void TearDown() override { fs::remove_all(root_); }

  gen::GeneratorStats generate(const std::string& name, uint64_t n, uint64_t seed, TexelFormat format,
                               unsigned threads) {
    gen::GeneratorOptions o;
    o.out = root_ / name;
    o.texture_count = n;
    o.seed = seed;
    o.format = format;
    o.threads = threads;
    auto r = gen::generate_scene(o);
    EXPECT_TRUE(r.ok()) << r.error().message;
    return r.ok() ? *r : gen::GeneratorStats{};
  }

  fs::path root_;
};

}  // namespace

TEST(MipChain, FiltersInLinearLight) {
  // Black and white averaged in linear light is 0.5 linear = sRGB code 188; averaging the codes would give 128.
  const uint32_t src[2] = {0xff000000u, 0xffffffffu};
  uint32_t dst = 0;
  gen::downsample_linear(src, 2, 1, &dst, 1, 1);
  EXPECT_EQ(dst & 0xff, 188u);
  EXPECT_EQ((dst >> 8) & 0xff, 188u);
  EXPECT_EQ(dst >> 24, 255u);
  for (int v = 0; v < 256; ++v) EXPECT_EQ(gen::linear_to_srgb8(gen::srgb8_to_linear(static_cast<uint8_t>(v))), v);
  // The table-driven encoder equals rounding the exact transfer function (away from exact half-way ties).
  for (int i = 0; i <= 200000; ++i) {
    const float lin = static_cast<float>(i) / 200000.0f;
    const float exact = gen::linear_to_srgb(lin) * 255.0f;
    if (std::fabs(exact - std::floor(exact) - 0.5f) < 1e-3f) continue;
    ASSERT_EQ(gen::linear_to_srgb8(lin), static_cast<int>(std::lround(exact))) << "linear " << lin;
  }
}

TEST(MipChain, HandlesOddAndThinSides) {
  // 3x1 -> 1x1 must average all three texels (the odd side's leftover is not dropped).
  const uint32_t src[3] = {0xff000000u, 0xff000000u, 0xff0000ffu};
  uint32_t dst = 0;
  gen::downsample_linear(src, 3, 1, &dst, 1, 1);
  EXPECT_EQ(dst & 0xff, gen::linear_to_srgb8(1.0f / 3.0f));
  // A 1-wide chain: 1x8 -> 1x4 -> 1x2 -> 1x1, every level a vertical average.
  std::vector<uint32_t> chain(8 + 4 + 2 + 1);
  for (uint32_t y = 0; y < 8; ++y) chain[y] = 0xff000000u | (y < 4 ? 0xffu : 0u);
  gen::build_mip_chain(1, 8, chain);
  EXPECT_EQ(chain[8] & 0xff, 255u);
  EXPECT_EQ(chain[11] & 0xff, 0u);
  EXPECT_EQ(chain[14] & 0xff, 188u);
}

TEST(Layout, ProducesExactlyTheRequestedTextureCount) {
  for (uint64_t n : {1ull, 2ull, 3ull, 4ull, 5ull, 7ull, 11ull, 301ull, 4099ull}) {
    const gen::CityLayout city = gen::generate_layout(42, n);
    ASSERT_EQ(city.surfaces.size(), n);
    for (const auto& s : city.surfaces) {
      EXPECT_GE(s.width_px, gen::kMinExtent);
      EXPECT_LE(s.width_px, gen::kMaxExtent);
      EXPECT_EQ(s.width_px & (s.width_px - 1), 0) << "not a power of two";
      EXPECT_EQ(s.height_px & (s.height_px - 1), 0) << "not a power of two";
    }
  }
}

TEST(Layout, ExtentsSpanTheSeedRangeAndAreMostlyNonSquare) {
  const gen::CityLayout city = gen::generate_layout(1, 20000);
  std::array<uint64_t, 16> sides{};
  uint64_t square = 0;
  std::vector<uint32_t> max_sides;
  for (const auto& s : city.surfaces) {
    sides[floor_log2(s.width_px)]++;
    sides[floor_log2(s.height_px)]++;
    max_sides.push_back(std::max(s.width_px, s.height_px));
    if (s.width_px == s.height_px) ++square;
  }
  EXPECT_LT(square * 2, city.surfaces.size()) << "most textures must be non-square";
  EXPECT_GT(sides[2], 0u) << "no 2^2 sides";
  EXPECT_GT(sides[9], 0u) << "no 2^9 sides";
  std::nth_element(max_sides.begin(), max_sides.begin() + static_cast<long>(max_sides.size() / 2), max_sides.end());
  const uint32_t median = max_sides[max_sides.size() / 2];
  EXPECT_GE(median, 64u);
  EXPECT_LE(median, 256u);
}

TEST_F(GeneratorTest, SameSeedSameBytesAnyThreadCount) {
  generate("a", 300, 7, TexelFormat::kBc1, 1);
  generate("b", 300, 7, TexelFormat::kBc1, 2);
  generate("c", 300, 8, TexelFormat::kBc1, 2);
  const uint64_t a = hash_tree(root_ / "a"), b = hash_tree(root_ / "b"), c = hash_tree(root_ / "c");
  EXPECT_EQ(a, b) << "1 thread and 2 threads must write identical files";
  EXPECT_NE(a, c) << "a different seed must give a different city";
}

TEST_F(GeneratorTest, FilesAgreeWithEachOther) {
  const auto stats = generate("s", 300, 3, TexelFormat::kRgba8, 2);
  const fs::path dir = root_ / "s";
  auto manifest = scene::read_manifest(dir);
  ASSERT_TRUE(manifest.ok()) << manifest.error().message;
  EXPECT_EQ(manifest->texture_count, 300u);
  EXPECT_EQ(manifest->mesh_count, 300u);
  EXPECT_EQ(manifest->texture_format, TexelFormat::kRgba8);
  EXPECT_GT(manifest->bounds_min[0], 390000.0);  // map coordinates, not city-local ones
  auto meshes = scene::read_meshes(dir);
  ASSERT_TRUE(meshes.ok()) << meshes.error().message;
  ASSERT_EQ(meshes->meshes.size(), 300u);
  EXPECT_EQ(stats.triangles, meshes->indices.size() / 3);
  for (size_t k = 0; k < meshes->meshes.size(); ++k) EXPECT_EQ(meshes->meshes[k].texture_id, k);
  auto table = scene::read_texture_table(dir);
  ASSERT_TRUE(table.ok()) << table.error().message;
  ASSERT_EQ(table->size(), 300u);
  auto colormap = scene::read_colormap(dir, 300);
  ASSERT_TRUE(colormap.ok()) << colormap.error().message;

  size_t flat = 0;
  for (uint32_t id = 0; id < 300; ++id) {
    const scene::TextureRecord& t = (*table)[id];
    const fs::path p = scene::texture_path(dir, TextureId{id});
    const auto bytes = read_all(p);
    ASSERT_GE(bytes.size(), scene::kDdsHeaderBytes) << p;
    auto info = scene::parse_dds_layout(std::as_bytes(std::span(bytes)), p.string());
    ASSERT_TRUE(info.ok()) << info.error().message;
    EXPECT_EQ(info->width, t.width);
    EXPECT_EQ(info->height, t.height);
    EXPECT_EQ(info->mip_count, t.mip_count);
    EXPECT_EQ(info->encoding, scene::DdsEncoding::kRgba8);
    EXPECT_EQ(info->data_offset, scene::kDdsHeaderBytes);
    ASSERT_EQ(bytes.size(), scene::dds_file_bytes(TexelFormat::kRgba8, t.width, t.height, t.mip_count)) << p;

    // Each mip is the linear-light box filter of the one before.
    for (uint32_t l = 1; l < t.mip_count; ++l) {
      const Extent2D s = mip_extent(t.width, t.height, l - 1), d = mip_extent(t.width, t.height, l);
      std::vector<uint32_t> src(size_t{s.width} * s.height), want(size_t{d.width} * d.height), got(want.size());
      std::memcpy(src.data(), bytes.data() + scene::dds_mip_offset(TexelFormat::kRgba8, t.width, t.height, l - 1),
                  src.size() * 4);
      std::memcpy(got.data(), bytes.data() + scene::dds_mip_offset(TexelFormat::kRgba8, t.width, t.height, l),
                  got.size() * 4);
      gen::downsample_linear(src.data(), s.width, s.height, want.data(), d.width, d.height);
      ASSERT_EQ(got, want) << p << " mip " << l;
    }
    // The colormap entry is the 1x1 mip.
    uint32_t last;
    std::memcpy(&last, bytes.data() + bytes.size() - 4, 4);
    EXPECT_EQ((*colormap)[id], last) << p;

    // Not flat: the luma of mip 0 varies (variance in 8-bit units squared).
    double sum = 0, sum2 = 0;
    const size_t n = size_t{t.width} * t.height;
    for (size_t i = 0; i < n; ++i) {
      const uint8_t* px = reinterpret_cast<const uint8_t*>(bytes.data()) + scene::kDdsHeaderBytes + 4 * i;
      const double y = 0.2126 * px[0] + 0.7152 * px[1] + 0.0722 * px[2];
      sum += y;
      sum2 += y * y;
    }
    const double var = sum2 / static_cast<double>(n) - (sum / static_cast<double>(n)) * (sum / static_cast<double>(n));
    if (var < 4.0) ++flat;
  }
  EXPECT_EQ(flat, 0u) << "textures with (almost) no detail in mip 0";
}

TEST_F(GeneratorTest, Bc1FilesMatchTableAndColormap) {
  generate("s", 120, 5, TexelFormat::kBc1, 2);
  const fs::path dir = root_ / "s";
  auto table = scene::read_texture_table(dir);
  ASSERT_TRUE(table.ok()) << table.error().message;
  auto colormap = scene::read_colormap(dir, 120);
  ASSERT_TRUE(colormap.ok());
  for (uint32_t id = 0; id < 120; ++id) {
    const scene::TextureRecord& t = (*table)[id];
    EXPECT_EQ(t.format, static_cast<uint32_t>(TexelFormat::kBc1));
    const fs::path p = scene::texture_path(dir, TextureId{id});
    const auto bytes = read_all(p);
    auto info = scene::parse_dds_layout(std::as_bytes(std::span(bytes)), p.string());
    ASSERT_TRUE(info.ok()) << info.error().message;
    EXPECT_EQ(info->encoding, scene::DdsEncoding::kBc1);
    EXPECT_EQ(info->data_offset, scene::kDdsHeaderBytes);
    EXPECT_EQ(info->width, t.width);
    EXPECT_EQ(info->height, t.height);
    EXPECT_EQ(info->mip_count, t.mip_count);
    ASSERT_EQ(bytes.size(), scene::dds_file_bytes(TexelFormat::kBc1, t.width, t.height, t.mip_count));
    // The last 8 bytes are the 1x1 mip's BC1 block: decoded, its texel must be the colormap entry to within
    // BC1's precision (565 endpoints, 1/3 interpolation).
    uint8_t block[8];
    std::memcpy(block, bytes.data() + bytes.size() - 8, 8);
    const auto decoded = decode_bc1_texel0(block);
    const uint32_t ref = (*colormap)[id];
    for (int ch = 0; ch < 3; ++ch)
      EXPECT_NEAR(decoded[static_cast<size_t>(ch)], static_cast<int>((ref >> (8 * ch)) & 0xff), 6)
          << p << " channel " << ch;
  }
}

TEST_F(GeneratorTest, RefusesNonEmptyFolderWithoutForce) {
  fs::create_directories(root_ / "x");
  std::ofstream(root_ / "x" / "keep.txt") << "user file";
  gen::GeneratorOptions o;
  o.out = root_ / "x";
  o.texture_count = 10;
  o.threads = 1;
  auto r = gen::generate_scene(o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("--force"), std::string::npos) << r.error().message;
  o.force = true;
  auto forced = gen::generate_scene(o);
  ASSERT_TRUE(forced.ok()) << forced.error().message;
  EXPECT_TRUE(fs::exists(root_ / "x" / "keep.txt"));  // --force replaces a scene, not the user's other files
  // A second forced run over a bigger previous scene leaves no stale textures behind.
  o.texture_count = 5;
  ASSERT_TRUE(gen::generate_scene(o).ok());
  EXPECT_FALSE(fs::exists(scene::texture_path(root_ / "x", TextureId{7})));
  EXPECT_TRUE(fs::exists(scene::texture_path(root_ / "x", TextureId{4})));
}

TEST_F(GeneratorTest, DefaultCameraPathHasPausesAndCuts) {
  generate("s", 300, 11, TexelFormat::kBc1, 2);
  auto path = CameraPath::load(root_ / "s" / "camera_path.txt");
  ASSERT_TRUE(path.ok()) << path.error().message;
  EXPECT_GE(path->duration_s(), 40.0);
  EXPECT_LE(path->duration_s(), 60.0);
  int cuts = 0, pauses = 0;
  const auto& k = path->keys();
  for (size_t i = 1; i < k.size(); ++i) {
    const bool same_time = k[i].time_s == k[i - 1].time_s;
    const bool same_pose = std::memcmp(&k[i].pose, &k[i - 1].pose, sizeof(CameraPose)) == 0;
    if (same_time) ++cuts;
    if (!same_time && same_pose) {
      ++pauses;
      EXPECT_DOUBLE_EQ(k[i].time_s - k[i - 1].time_s, 2.0);
    }
  }
  EXPECT_EQ(cuts, 4);
  EXPECT_EQ(pauses, 4);
  for (const auto& key : k) {
    const double alt = key.pose.position[2] - 34.0;
    EXPECT_GE(alt, 30.0);
    EXPECT_LE(alt, 130.0);
    EXPECT_LT(key.pose.pitch_deg, -15.0);
    EXPECT_GT(key.pose.pitch_deg, -40.0);
  }
}
