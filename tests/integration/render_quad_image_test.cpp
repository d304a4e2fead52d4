// THE key image test. A scene written with the scene_format writers holds one quad that faces a still camera
// and covers a known rectangle of pixels, textured with an RGBA8 DDS of a known pattern. After texstream-render
// has streamed the texture from the real texstream-server down to the level the rectangle shows 1:1, the quad's
// pixels in the last PNG must equal that level resampled to the rectangle, within mean abs error < 4/255 and
// PSNR > 30 dB. Two cases: 256² shown at mip 0; 2048 x 1024 shown at mip 2 (512 x 256 pixels) with the default
// profile: a non-square texture four times the old layer side whose level is twice the old 1 MiB staging slot
// (issue 26: any texture the device samples fits, with the defaults). Lighting is exactly 1 for a camera-facing quad
// and Eq. 8 gives the colormap no weight at mip 0, so neither may change a texel. On failure, actual, expected and diff
// PNGs are written next to the test output and their paths printed.
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>
#include "process_test_support.hpp"

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <vector>

#define STB_IMAGE_IMPLEMENTATION
#include <stb_image.h>
#include <stb_image_write.h>  // its implementation comes with texstream::renderer (frame_capture.cpp)

#include "texstream/common/scene_format.hpp"

namespace fs = std::filesystem;
using namespace texstream;

namespace {

const fs::path kBin = TEXSTREAM_BIN_DIR;
using texstream::test::slurp;
int run(const std::string& cmd, const fs::path& log) { return texstream::test::run_logged(cmd, log); }
constexpr int kWidth = 960, kHeight = 540;
constexpr double kFovY = 60.0;
constexpr double kDistance = 100.0;                                  // camera to quad, metres
constexpr double kCamX = 392000.0, kCamY = 5820000.0, kCamZ = 50.0;  // map coordinates: large offsets on purpose

struct Rgba {
  uint8_t r, g, b, a;
};

// A texture of tex_w x tex_h texels shown at `level`: the quad covers (tex_w >> level) x (tex_h >> level) pixels.
struct QuadCase {
  const char* name;
  uint32_t tex_w, tex_h, level;
  double rect_w() const { return static_cast<double>(tex_w >> level); }
  double rect_h() const { return static_cast<double>(tex_h >> level); }
};

struct Level {
  uint32_t w, h;
  std::vector<Rgba> texels;
};

// Pattern: red = x, green = y (smooth gradients, wrapping every 256), blue = a 32-texel checker (sharp edges).
Rgba texel(uint32_t x, uint32_t y) {
  const bool dark = ((x / 32) + (y / 32)) % 2 == 0;
  return {static_cast<uint8_t>(x), static_cast<uint8_t>(y), static_cast<uint8_t>(dark ? 40 : 220), 255};
}

// Box-filtered chain down to 1 x 1 (a side at 1 stays 1).
std::vector<Level> mip_chain(uint32_t tex_w, uint32_t tex_h) {
  std::vector<Level> mips;
  Level l0{tex_w, tex_h, std::vector<Rgba>(size_t{tex_w} * tex_h)};
  for (uint32_t y = 0; y < tex_h; ++y)
    for (uint32_t x = 0; x < tex_w; ++x) l0.texels[size_t{y} * tex_w + x] = texel(x, y);
  mips.push_back(std::move(l0));
  while (mips.back().w > 1 || mips.back().h > 1) {
    const Level& prev = mips.back();
    Level next{std::max(prev.w / 2, 1u), std::max(prev.h / 2, 1u), {}};
    next.texels.resize(size_t{next.w} * next.h);
    for (uint32_t y = 0; y < next.h; ++y)
      for (uint32_t x = 0; x < next.w; ++x) {
        int sum[4] = {0, 0, 0, 0}, n = 0;
        for (uint32_t dy = 0; dy < 2; ++dy)
          for (uint32_t dx = 0; dx < 2; ++dx) {
            const uint32_t px = std::min(2 * x + dx, prev.w - 1), py = std::min(2 * y + dy, prev.h - 1);
            const Rgba& p = prev.texels[size_t{py} * prev.w + px];
            sum[0] += p.r, sum[1] += p.g, sum[2] += p.b, sum[3] += p.a, ++n;
          }
        next.texels[size_t{y} * next.w + x] = {static_cast<uint8_t>(sum[0] / n), static_cast<uint8_t>(sum[1] / n),
                                               static_cast<uint8_t>(sum[2] / n), static_cast<uint8_t>(sum[3] / n)};
      }
    mips.push_back(std::move(next));
  }
  return mips;
}

double focal_px() { return (kHeight / 2.0) / std::tan(kFovY * M_PI / 360.0); }

// The still camera of these tests, lock-step, validation on, controller off: `frames` frames of `scene`, the last
// one written (frame_<frames - 1>.png under out/frames), plus `sets`.
std::string still_render_cmd(const fs::path& scene, const fs::path& out, int frames, const std::string& sets) {
  return (kBin / "texstream-render").string() + " --set scene.dir=" + scene.string() +
         " --set render.validation=true --set render.lockstep=true --set controller.mode=none" +
         " --set render.frames=" + std::to_string(frames) + " --set render.write_every_frames=0" +
         " --set render.width_px=" + std::to_string(kWidth) + " --set render.height_px=" + std::to_string(kHeight) +
         " --set render.fov_y_deg=" + std::to_string(kFovY) + " --set render.output_dir=" + out.string() + sets;
}

void write_scene(const fs::path& dir, const QuadCase& q) {
  const double half_w = kDistance * (q.rect_w() / 2.0) / focal_px();  // quad half-size in metres
  const double half_h = kDistance * (q.rect_h() / 2.0) / focal_px();
  const auto hw = static_cast<float>(half_w), hh = static_cast<float>(half_h);
  scene::MeshData md;
  scene::MeshRecord m{};
  m.origin[0] = kCamX;
  m.origin[1] = kCamY + kDistance;  // straight ahead of a camera looking north
  m.origin[2] = kCamZ;
  m.bounds_min[0] = -hw, m.bounds_min[1] = 0, m.bounds_min[2] = -hh;
  m.bounds_max[0] = hw, m.bounds_max[1] = 0, m.bounds_max[2] = hh;
  m.vertex_count = 4;
  m.index_count = 6;
  m.texture_id = 0;
  md.meshes.push_back(m);
  // Normal towards the camera; uv (0, 0) at the top-left corner as seen: texture row 0 at the top.
  md.vertices = {{{-hw, 0, hh}, {0, -1, 0}, {0, 0}},
                 {{hw, 0, hh}, {0, -1, 0}, {1, 0}},
                 {{hw, 0, -hh}, {0, -1, 0}, {1, 1}},
                 {{-hw, 0, -hh}, {0, -1, 0}, {0, 1}}};
  md.indices = {0, 1, 2, 0, 2, 3};
  ASSERT_TRUE(scene::write_meshes(dir, md).ok());

  const uint32_t mips = full_mip_count(q.tex_w, q.tex_h);
  const scene::TextureRecord rec{q.tex_w, q.tex_h, mips, static_cast<uint32_t>(TexelFormat::kRgba8)};
  ASSERT_TRUE(scene::write_texture_table(dir, std::span(&rec, 1)).ok());
  const auto chain = mip_chain(q.tex_w, q.tex_h);
  ASSERT_EQ(chain.size(), mips);
  const Rgba avg = chain.back().texels[0];
  const uint32_t colour = avg.r | (avg.g << 8) | (avg.b << 16) | (255u << 24);
  ASSERT_TRUE(scene::write_colormap(dir, std::span(&colour, 1)).ok());

  const fs::path dds = scene::texture_path(dir, TextureId(0));
  fs::create_directories(dds.parent_path());
  std::ofstream out(dds, std::ios::binary);
  const auto header = scene::make_dds_header(TexelFormat::kRgba8, q.tex_w, q.tex_h, mips);
  out.write(reinterpret_cast<const char*>(header.data()), header.size());
  for (const auto& level : chain)
    out.write(reinterpret_cast<const char*>(level.texels.data()),
              static_cast<std::streamsize>(level.texels.size() * 4));
  ASSERT_TRUE(out.good());
  out.close();

  std::ofstream(dir / "camera_path.txt") << "# still camera looking north at the quad\n"
                                         << std::fixed << "0 " << kCamX << " " << kCamY << " " << kCamZ << " 0 0\n"
                                         << "1000 " << kCamX << " " << kCamY << " " << kCamZ << " 0 0\n";
  scene::Manifest man;
  man.name = "render quad image test";
  man.mesh_count = 1;
  man.texture_count = 1;
  man.texture_format = TexelFormat::kRgba8;
  man.origin = {kCamX, kCamY, kCamZ};
  man.bounds_min = {kCamX - half_w, kCamY + kDistance, kCamZ - half_h};
  man.bounds_max = {kCamX + half_w, kCamY + kDistance, kCamZ + half_h};
  ASSERT_TRUE(scene::write_manifest(dir, man).ok());
}

// Bilinear sample of a level at texel coordinates (tx, ty) (texel centres at +0.5), edges clamped.
std::array<double, 3> sample(const Level& l, double tx, double ty) {
  const double fx = std::clamp(tx - 0.5, 0.0, l.w - 1.0), fy = std::clamp(ty - 0.5, 0.0, l.h - 1.0);
  const auto x0 = static_cast<uint32_t>(fx), y0 = static_cast<uint32_t>(fy);
  const uint32_t x1 = std::min(x0 + 1, l.w - 1), y1 = std::min(y0 + 1, l.h - 1);
  const double ax = fx - x0, ay = fy - y0;
  std::array<double, 3> out{};
  for (int c = 0; c < 3; ++c) {
    auto ch = [&](uint32_t x, uint32_t y) {
      const Rgba& p = l.texels[size_t{y} * l.w + x];
      return static_cast<double>(c == 0 ? p.r : c == 1 ? p.g : p.b);
    };
    out[c] = (1 - ay) * ((1 - ax) * ch(x0, y0) + ax * ch(x1, y0)) + ay * ((1 - ax) * ch(x0, y1) + ax * ch(x1, y1));
  }
  return out;
}

class RenderQuadImage : public ::testing::TestWithParam<QuadCase> {};

}  // namespace

TEST_P(RenderQuadImage, TheLevelShownMatchesTheTextureOnScreen) {
  const QuadCase q = GetParam();
  const fs::path dir =
      fs::temp_directory_path() / ("texstream_render_quad_" + std::string(q.name) + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir / "scene");
  write_scene(dir / "scene", q);
  if (HasFatalFailure()) return;

  const fs::path out = dir / "out";
  const std::string cmd = still_render_cmd(dir / "scene", out, 60, " --set cache.format=rgba8");
  const int rc = run(cmd, dir / "render.log");
  const std::string log = slurp(dir / "render.log");
  ASSERT_EQ(rc, 0) << log;
  const auto summary = nlohmann::json::parse(slurp(out / "summary.json"));
  EXPECT_EQ(summary["validation_errors"].get<int>(), 0) << log;
  ASSERT_EQ(summary["textures_resident"].get<int>(), 1) << log;

  int w = 0, h = 0, n = 0;
  const fs::path png = out / "frames" / "frame_00059.png";
  unsigned char* pixels = stbi_load(png.c_str(), &w, &h, &n, 4);
  ASSERT_NE(pixels, nullptr) << png;
  ASSERT_EQ(w, kWidth);
  ASSERT_EQ(h, kHeight);

  // Where the quad lands: a camera-facing rectangle of rect_w x rect_h pixels centred on the screen.
  const double x0 = kWidth / 2.0 - q.rect_w() / 2.0, y0 = kHeight / 2.0 - q.rect_h() / 2.0;
  const auto chain = mip_chain(q.tex_w, q.tex_h);
  const Level& shown = chain[q.level];
  // One pixel of margin: edge pixels are partly covered / clamped and say nothing about the texels.
  const int px0 = static_cast<int>(x0) + 1, px1 = static_cast<int>(x0 + q.rect_w()) - 1;
  const int py0 = static_cast<int>(y0) + 1, py1 = static_cast<int>(y0 + q.rect_h()) - 1;
  const int rw = px1 - px0, rh = py1 - py0;
  std::vector<unsigned char> actual(rw * rh * 4), expected(rw * rh * 4), diff(rw * rh * 4);
  double abs_sum = 0, sq_sum = 0;
  for (int y = py0; y < py1; ++y)
    for (int x = px0; x < px1; ++x) {
      const double u = (x + 0.5 - x0) / q.rect_w(), v = (y + 0.5 - y0) / q.rect_h();
      const auto e = sample(shown, u * shown.w, v * shown.h);
      const unsigned char* a = pixels + (static_cast<size_t>(y) * w + x) * 4;
      const size_t o = (static_cast<size_t>(y - py0) * rw + (x - px0)) * 4;
      for (int c = 0; c < 3; ++c) {
        const double d = a[c] - e[c];
        abs_sum += std::abs(d);
        sq_sum += d * d;
        actual[o + c] = a[c];
        expected[o + c] = static_cast<unsigned char>(std::lround(e[c]));
        diff[o + c] = static_cast<unsigned char>(std::min(255.0, std::abs(d) * 8));  // x8 to make small errors visible
      }
      actual[o + 3] = expected[o + 3] = diff[o + 3] = 255;
    }
  const double count = 3.0 * rw * rh;
  const double mae = abs_sum / count;
  const double mse = sq_sum / count;
  const double psnr = mse > 0 ? 10.0 * std::log10(255.0 * 255.0 / mse) : 99.0;
  // A pixel well outside the quad is background, not texture: the comparison above is not vacuous.
  const unsigned char* outside = pixels + (static_cast<size_t>(20) * w + 20) * 4;
  const bool background_differs = std::abs(outside[0] - 20) + std::abs(outside[1] - 20) > 0;
  stbi_image_free(pixels);
  EXPECT_TRUE(background_differs);

  std::printf("quad image %s: mean abs error %.3f / 255, PSNR %.2f dB over %d x %d pixels\n", q.name, mae, psnr, rw,
              rh);
  const bool pass = mae < 4.0 && psnr > 30.0;
  if (!pass) {
    const fs::path a = dir / "quad_actual.png", e = dir / "quad_expected.png", d = dir / "quad_diff_x8.png";
    stbi_write_png(a.c_str(), rw, rh, 4, actual.data(), rw * 4);
    stbi_write_png(e.c_str(), rw, rh, 4, expected.data(), rw * 4);
    stbi_write_png(d.c_str(), rw, rh, 4, diff.data(), rw * 4);
    ADD_FAILURE() << "quad pixels differ from the texture: MAE " << mae << "/255, PSNR " << psnr << " dB\n"
                  << "  actual:   " << a << "\n  expected: " << e << "\n  diff x8:  " << d << "\n"
                  << log;
    return;  // keep the folder for inspection
  }
  fs::remove_all(dir);
}

namespace {
INSTANTIATE_TEST_SUITE_P(Textures, RenderQuadImage,
                         ::testing::Values(QuadCase{"square256_mip0", 256, 256, 0},
                                           QuadCase{"wide2048x1024_mip2", 2048, 1024, 2}),
                         [](const auto& p) { return std::string(p.param.name); });
}  // namespace

// BC7 served raw (issue 27: "BC7 served raw where the device supports it"): the same quad with a 256² BC7
// texture in a DDS with the DX10 extension (DXGI_FORMAT_BC7_UNORM_SRGB), every block of a level one solid
// colour (mode 6, both endpoints the colour, all indices 0), a different colour per level. The renderer's cache is
// a BC7 image; the quad shows level 0, so its pixels must be level 0's colour.
namespace {

// A BC7 mode-6 block of one colour; each channel odd (mode 6 endpoints are 7 bits plus a shared low bit, here 1).
std::array<uint8_t, 16> bc7_solid(uint8_t r, uint8_t g, uint8_t b) {
  std::array<uint8_t, 16> block{};
  uint32_t at = 0;
  auto put = [&](uint32_t value, uint32_t bits) {
    for (uint32_t i = 0; i < bits; ++i, ++at)
      if ((value >> i) & 1u) block[at / 8] |= static_cast<uint8_t>(1u << (at % 8));
  };
  put(1u << 6, 7);  // mode 6
  for (uint8_t c : {r, g, b, uint8_t{255}}) {
    put(c >> 1, 7);  // endpoint 0
    put(c >> 1, 7);  // endpoint 1
  }
  put(1, 1);  // p0
  put(1, 1);  // p1; the 63 index bits stay 0
  return block;
}

}  // namespace

TEST(RenderQuadBc7, ABc7TextureIsServedRawAndShowsItsLevelsColour) {
  const QuadCase q{"bc7", 256, 256, 0};
  const fs::path dir = fs::temp_directory_path() / ("texstream_render_quad_bc7_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir / "scene");
  write_scene(dir / "scene", q);
  if (HasFatalFailure()) return;
  const uint32_t mips = full_mip_count(256, 256);
  const scene::TextureRecord rec{256, 256, mips, static_cast<uint32_t>(TexelFormat::kBc7)};
  ASSERT_TRUE(scene::write_texture_table(dir / "scene", std::span(&rec, 1)).ok());
  auto man = scene::read_manifest(dir / "scene");
  ASSERT_TRUE(man.ok());
  man->texture_format = TexelFormat::kBc7;
  ASSERT_TRUE(scene::write_manifest(dir / "scene", *man).ok());
  {
    std::ofstream out(scene::texture_path(dir / "scene", TextureId(0)), std::ios::binary | std::ios::trunc);
    auto header = scene::make_dds_header(TexelFormat::kBc3, 256, 256, mips);
    const uint32_t dx10 = 0x30315844u;  // "DX10"
    std::memcpy(header.data() + scene::dds_field::kPfFourCC, &dx10, 4);
    out.write(reinterpret_cast<const char*>(header.data()), static_cast<std::streamsize>(header.size()));
    const uint32_t ext[5] = {99, 3, 0, 1, 0};  // BC7_UNORM_SRGB, TEXTURE2D, no flags, one texture, alpha unknown
    out.write(reinterpret_cast<const char*>(ext), sizeof ext);
    for (uint32_t l = 0; l < mips; ++l) {
      const auto block = bc7_solid(static_cast<uint8_t>(201 - 20 * l), static_cast<uint8_t>(101 + 10 * l), 51);
      const uint64_t blocks = mip_bytes(TexelFormat::kBc7, 256, 256, l) / 16;
      for (uint64_t b = 0; b < blocks; ++b) out.write(reinterpret_cast<const char*>(block.data()), 16);
    }
  }
  const fs::path out = dir / "out";
  const std::string cmd = still_render_cmd(dir / "scene", out, 40, "");
  const int rc = run(cmd, dir / "render.log");
  const std::string log = slurp(dir / "render.log");
  ASSERT_EQ(rc, 0) << log;
  const auto summary = nlohmann::json::parse(slurp(out / "summary.json"));
  EXPECT_EQ(summary["validation_errors"].get<int>(), 0) << log;
  EXPECT_EQ(summary["textures_resident"].get<int>(), 1) << log;
  int w = 0, h = 0, n = 0;
  unsigned char* pixels = stbi_load((out / "frames" / "frame_00039.png").c_str(), &w, &h, &n, 4);
  ASSERT_NE(pixels, nullptr);
  const unsigned char* c = pixels + (static_cast<size_t>(h / 2) * w + w / 2) * 4;
  const int got[3] = {c[0], c[1], c[2]};
  stbi_image_free(pixels);
  EXPECT_NEAR(got[0], 201, 2) << log;
  EXPECT_NEAR(got[1], 101, 2);
  EXPECT_NEAR(got[2], 51, 2);
  if (!HasFailure()) fs::remove_all(dir);
}

// Several texel formats in one scene (issue 27): four quads side by side, textures in RGBA8, BC1, BC3 and BC7,
// each level of each texture one solid colour. Each format gets its own cache image (plane) and nothing is
// decoded: every quad must show its texture's level-0 colour (so the shader read the right image at the right
// layer), every mip must reach the GPU in its own format (bytes uploaded = bytes in the files), and cache.json
// must list the four planes.
namespace {

struct MixedTexture {
  TexelFormat format;
  std::array<uint8_t, 3> colour;  // level 0; representable exactly in every format (BC1: 5-6-5 bits)
};

// BC1 block of one colour: both endpoints the colour, all indices 0.
std::array<uint8_t, 8> bc1_solid(uint8_t r, uint8_t g, uint8_t b) {
  const auto c = static_cast<uint16_t>(((r >> 3) << 11) | ((g >> 2) << 5) | (b >> 3));
  return {static_cast<uint8_t>(c & 0xff),
          static_cast<uint8_t>(c >> 8),
          static_cast<uint8_t>(c & 0xff),
          static_cast<uint8_t>(c >> 8),
          0,
          0,
          0,
          0};
}

// A colour whose 5-6-5 rounding is exact: each channel's low bits repeat its high bits, as the expansion does.
std::array<uint8_t, 3> exact565(uint8_t r5, uint8_t g6, uint8_t b5) {
  return {static_cast<uint8_t>((r5 << 3) | (r5 >> 2)), static_cast<uint8_t>((g6 << 2) | (g6 >> 4)),
          static_cast<uint8_t>((b5 << 3) | (b5 >> 2))};
}

// Level l's colour: level 0's, darkened per level so that showing a wrong level is seen too.
std::array<uint8_t, 3> level_colour(const MixedTexture& t, uint32_t l) {
  if (l == 0) return t.colour;
  const uint8_t v = static_cast<uint8_t>(31 - 2 * std::min(l, 15u));
  return t.format == TexelFormat::kBc7 ? std::array<uint8_t, 3>{static_cast<uint8_t>(2 * v + 1), 1, 1}
                                       : exact565(v, 0, 0);
}

std::vector<uint8_t> level_bytes(const MixedTexture& t, uint32_t side, uint32_t l) {
  const auto c = level_colour(t, l);
  const uint64_t bytes = mip_bytes(t.format, side, side, l);
  std::vector<uint8_t> out;
  out.reserve(bytes);
  while (out.size() < bytes) {
    if (t.format == TexelFormat::kRgba8) {
      out.insert(out.end(), {c[0], c[1], c[2], 255});
    } else if (t.format == TexelFormat::kBc1) {
      const auto b = bc1_solid(c[0], c[1], c[2]);
      out.insert(out.end(), b.begin(), b.end());
    } else if (t.format == TexelFormat::kBc3) {
      const std::array<uint8_t, 8> alpha{255, 255, 0, 0, 0, 0, 0, 0};  // alpha0 everywhere
      const auto b = bc1_solid(c[0], c[1], c[2]);
      out.insert(out.end(), alpha.begin(), alpha.end());
      out.insert(out.end(), b.begin(), b.end());
    } else {
      const auto b = bc7_solid(c[0], c[1], c[2]);
      out.insert(out.end(), b.begin(), b.end());
    }
  }
  return out;
}

}  // namespace

class RenderQuadMixedFormats : public ::testing::TestWithParam<std::string> {};

// Under lru every plane's layers are as large as the address space allows; under ring (the seed's eviction) a
// plane's layer is its largest texture, so the planes here have layers of 64, 128, 32 and 64 texels and the
// shader must use each texture's own plane's size.
TEST_P(RenderQuadMixedFormats, EveryTextureIsDrawnFromTheImageOfItsOwnFormat) {
  const std::array<MixedTexture, 4> textures{{{TexelFormat::kRgba8, {201, 101, 51}},
                                              {TexelFormat::kBc1, exact565(4, 40, 28)},
                                              {TexelFormat::kBc3, exact565(28, 60, 4)},
                                              {TexelFormat::kBc7, {51, 151, 201}}}};
  // Texture sides (shown at level 0: as many pixels on screen) and quad centres, pixels right of the middle.
  constexpr std::array<uint32_t, 4> kSide{64, 128, 32, 64};
  constexpr std::array<double, 4> kCentrePx{-240, -80, 60, 180};
  const fs::path dir =
      fs::temp_directory_path() / ("texstream_render_quad_mixed_" + GetParam() + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const fs::path scene_dir = dir / "scene";
  fs::create_directories(scene_dir);
  const double metres_per_px = kDistance / focal_px();
  scene::MeshData md;
  std::vector<scene::TextureRecord> records;
  std::vector<uint32_t> colours;
  uint64_t file_bytes = 0;
  for (uint32_t k = 0; k < textures.size(); ++k) {
    const uint32_t mips = full_mip_count(kSide[k], kSide[k]);
    const auto h = static_cast<float>(metres_per_px * kSide[k] / 2.0);
    scene::MeshRecord m{};
    m.origin[0] = kCamX + kCentrePx[k] * metres_per_px;
    m.origin[1] = kCamY + kDistance;
    m.origin[2] = kCamZ;
    m.bounds_min[0] = -h, m.bounds_min[2] = -h;
    m.bounds_max[0] = h, m.bounds_max[2] = h;
    m.first_vertex = 4 * k;
    m.vertex_count = 4;
    m.first_index = 6 * k;
    m.index_count = 6;
    m.texture_id = k;
    md.meshes.push_back(m);
    md.vertices.insert(md.vertices.end(), {{{-h, 0, h}, {0, -1, 0}, {0, 0}},
                                           {{h, 0, h}, {0, -1, 0}, {1, 0}},
                                           {{h, 0, -h}, {0, -1, 0}, {1, 1}},
                                           {{-h, 0, -h}, {0, -1, 0}, {0, 1}}});
    for (uint32_t i : {0u, 1u, 2u, 0u, 2u, 3u}) md.indices.push_back(i);
    records.push_back({kSide[k], kSide[k], mips, static_cast<uint32_t>(textures[k].format)});
    const auto c = level_colour(textures[k], mips - 1);
    colours.push_back(c[0] | (c[1] << 8) | (c[2] << 16) | (255u << 24));

    const fs::path dds = scene::texture_path(scene_dir, TextureId(k));
    fs::create_directories(dds.parent_path());
    std::ofstream out(dds, std::ios::binary);
    const bool bc7 = textures[k].format == TexelFormat::kBc7;
    auto header = scene::make_dds_header(bc7 ? TexelFormat::kBc3 : textures[k].format, kSide[k], kSide[k], mips);
    if (bc7) {
      const uint32_t dx10 = 0x30315844u;  // "DX10"
      std::memcpy(header.data() + scene::dds_field::kPfFourCC, &dx10, 4);
    }
    out.write(reinterpret_cast<const char*>(header.data()), static_cast<std::streamsize>(header.size()));
    if (bc7) {
      const uint32_t ext[5] = {99, 3, 0, 1, 0};  // BC7_UNORM_SRGB, TEXTURE2D, no flags, one texture, alpha unknown
      out.write(reinterpret_cast<const char*>(ext), sizeof ext);
    }
    for (uint32_t l = 0; l < mips; ++l) {
      const auto bytes = level_bytes(textures[k], kSide[k], l);
      out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
      // Streaming starts at the 4x4 level (seed 000 Algorithm 1), for every format.
      if ((kSide[k] >> l) >= 4) file_bytes += bytes.size();
    }
    ASSERT_TRUE(out.good());
  }
  ASSERT_TRUE(scene::write_meshes(scene_dir, md).ok());
  ASSERT_TRUE(scene::write_texture_table(scene_dir, records).ok());
  ASSERT_TRUE(scene::write_colormap(scene_dir, colours).ok());
  std::ofstream(scene_dir / "camera_path.txt") << std::fixed << "0 " << kCamX << " " << kCamY << " " << kCamZ
                                               << " 0 0\n1000 " << kCamX << " " << kCamY << " " << kCamZ << " 0 0\n";
  scene::Manifest man;
  man.name = "mixed formats";
  man.mesh_count = textures.size();
  man.texture_count = textures.size();
  man.texture_format = std::nullopt;  // "mixed"
  man.origin = {kCamX, kCamY, kCamZ};
  man.bounds_min = {kCamX - 400 * metres_per_px, kCamY + kDistance, kCamZ - 64 * metres_per_px};
  man.bounds_max = {kCamX + 400 * metres_per_px, kCamY + kDistance, kCamZ + 64 * metres_per_px};
  ASSERT_TRUE(scene::write_manifest(scene_dir, man).ok());
  ASSERT_EQ(scene::read_manifest(scene_dir)->texture_format, std::nullopt);

  const fs::path out = dir / "out";
  const std::string cmd = still_render_cmd(scene_dir, out, 40, " --set cache.eviction=" + GetParam());
  const int rc = run(cmd, dir / "render.log");
  const std::string log = slurp(dir / "render.log");
  ASSERT_EQ(rc, 0) << log;
  const auto summary = nlohmann::json::parse(slurp(out / "summary.json"));
  EXPECT_EQ(summary["validation_errors"].get<int>(), 0) << log;
  EXPECT_EQ(summary["textures_resident"].get<int>(), 4) << log;
  const auto cache = nlohmann::json::parse(slurp(out / "cache.json"));
  std::cout << "cache planes: " << cache["planes"].dump() << "\n";
  std::vector<std::string> planes;
  for (const auto& p : cache["planes"]) planes.push_back(p["format"].get<std::string>());
  std::sort(planes.begin(), planes.end());
  EXPECT_EQ(planes, (std::vector<std::string>{"bc1", "bc3", "bc7", "rgba8"}));
  // Every level from 4x4 down went to the GPU once, in the bytes of its file (nothing decoded).
  EXPECT_EQ(cache["bytes_uploaded"].get<uint64_t>(), file_bytes) << cache.dump(1);

  int w = 0, hgt = 0, n = 0;
  unsigned char* pixels = stbi_load((out / "frames" / "frame_00039.png").c_str(), &w, &hgt, &n, 4);
  ASSERT_NE(pixels, nullptr);
  for (uint32_t k = 0; k < textures.size(); ++k) {
    const auto x = static_cast<int>(std::lround(w / 2.0 + kCentrePx[k]));
    const unsigned char* c = pixels + (static_cast<size_t>(hgt / 2) * w + x) * 4;
    for (int ch = 0; ch < 3; ++ch)
      EXPECT_NEAR(c[ch], textures[k].colour[ch], 2)
          << "quad " << k << " (" << to_string(textures[k].format) << ") channel " << ch << "\n"
          << log;
  }
  stbi_image_free(pixels);
  if (!HasFailure()) fs::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Evictions, RenderQuadMixedFormats, ::testing::Values("lru", "ring"),
                         [](const auto& p) { return p.param; });
