// texstream-import's texel formats, without a renderer: a model built in memory (two PNGs the test writes, seven
// materials: opaque, MASK, BLEND, the same image opaque and alpha-tested, wrap-only twins, flat colours) through
// build_scene. With auto (the default) each texture record, its DDS header and its file size name the format its
// alpha needs (BC1 opaque, BC3 alpha-tested), wrap-only twins share one file and an image used opaque and masked
// does not, and the manifest says "mixed"; each file is the one the one-format run of its format writes; an
// explicit format is every texture's and the manifest's. The bytes are the same on two runs and 1 or 2 threads.
#include <gtest/gtest.h>

#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "scene_builder.hpp"
#include "test_temp_dir.hpp"
#include "texstream/common/dds.hpp"
#include "texstream/common/scene_format.hpp"

namespace texstream::import {
namespace {
namespace fs = std::filesystem;

// What each material of the model is, and what auto must make of it.
struct Case {
  const char* name;
  int image;  // -1: flat colour
  AlphaMode alpha;
  Wrap wrap;
  float base_alpha;
  TexelFormat auto_format;
};
constexpr std::array<Case, 7> kCases{{
    {"grid", 0, AlphaMode::kOpaque, Wrap::kRepeat, 1.0f, TexelFormat::kBc1},
    {"grid clamped", 0, AlphaMode::kOpaque, Wrap::kClamp, 1.0f, TexelFormat::kBc1},  // shares grid's file
    {"leaf", 1, AlphaMode::kMask, Wrap::kClamp, 1.0f, TexelFormat::kBc3},
    {"leaf opaque", 1, AlphaMode::kOpaque, Wrap::kClamp, 1.0f, TexelFormat::kBc1},  // same image, its own file
    {"leaf blend", 1, AlphaMode::kBlend, Wrap::kMirror, 1.0f, TexelFormat::kBc3},   // shares leaf's file
    {"plain", -1, AlphaMode::kOpaque, Wrap::kClamp, 1.0f, TexelFormat::kBc1},
    {"glass", -1, AlphaMode::kMask, Wrap::kClamp, 0.8f, TexelFormat::kBc3},
}};

std::string read_all(const fs::path& file) {
  std::string bytes(fs::file_size(file), '\0');
  std::ifstream(file, std::ios::binary).read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return bytes;
}

class ImportFormats : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::fresh_test_dir("texstream_import_formats");
    write_png(dir_ / "grid.png", [](int x, int y) {
      return std::array<uint8_t, 4>{static_cast<uint8_t>(x * 16), static_cast<uint8_t>(y * 16),
                                    static_cast<uint8_t>((x / 4 + y / 4) % 2 ? 200 : 40), 255};
    });
    write_png(dir_ / "leaf.png", [](int x, int y) {
      const int dx = 2 * x - 15, dy = 2 * y - 15;
      return std::array<uint8_t, 4>{static_cast<uint8_t>(40 + x * 8), 170, 50,
                                    static_cast<uint8_t>(dx * dx + dy * dy < 144 ? 255 : 0)};
    });
    model_.source = (dir_ / "model.gltf").string();
    for (const char* file : {"grid.png", "leaf.png"}) model_.images.push_back({file, dir_ / file, {}, {}});
    for (const Case& c : kCases) {
      Material m;
      m.name = c.name;
      m.image = c.image;
      m.base_colour = {0.9f, 0.8f, 0.7f, c.base_alpha};
      m.wrap_u = m.wrap_v = c.wrap;
      m.alpha = c.alpha;
      model_.materials.push_back(m);
      // One quad per material, placed once, side by side: mesh i has material i.
      const float x = 3.0f * static_cast<float>(model_.primitives.size());
      Primitive p;
      p.name = c.name;
      p.positions = {x, 0, 0, x + 2, 0, 0, x + 2, 2, 0, x, 2, 0};
      p.uvs = {0, 1, 1, 1, 1, 0, 0, 0};
      p.indices = {0, 1, 2, 0, 2, 3};
      p.material = static_cast<int>(model_.materials.size() - 1);
      model_.instances.push_back({static_cast<uint32_t>(model_.primitives.size()), kIdentity});
      model_.primitives.push_back(std::move(p));
    }
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(dir_);
  }

  template <typename Texel>
  void write_png(const fs::path& file, Texel texel) {
    std::vector<uint8_t> px(16 * 16 * 4);
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) {
        const auto t = texel(x, y);
        for (int k = 0; k < 4; ++k) px[static_cast<size_t>((y * 16 + x) * 4 + k)] = t[static_cast<size_t>(k)];
      }
    ASSERT_NE(stbi_write_png(file.c_str(), 16, 16, 4, px.data(), 16 * 4), 0);
  }

  Result<ImportReport> import(const std::string& out, std::optional<TexelFormat> format, unsigned threads = 2) {
    ImportOptions opt;
    opt.out = dir_ / out;
    opt.format = format;
    opt.threads = threads;
    return build_scene(model_, opt);
  }

  // The texture of each case (mesh i is case i).
  static std::vector<uint32_t> texture_of_cases(const fs::path& scene_dir) {
    const auto meshes = scene::read_meshes(scene_dir);
    EXPECT_TRUE(meshes.ok());
    std::vector<uint32_t> ids;
    if (meshes.ok())
      for (const auto& r : meshes->meshes) ids.push_back(r.texture_id);
    EXPECT_EQ(ids.size(), kCases.size());
    return ids;
  }

  // Each file of the scene folder by its path inside it.
  static std::map<std::string, std::string> files_of(const fs::path& scene_dir) {
    std::map<std::string, std::string> out;
    for (const auto& e : fs::recursive_directory_iterator(scene_dir))
      if (e.is_regular_file()) out[fs::relative(e.path(), scene_dir).string()] = read_all(e.path());
    return out;
  }

  // The texel format the DDS header of `texture` names, and whether the file is as long as the record says.
  static std::pair<TexelFormat, bool> dds_format(const fs::path& scene_dir, uint32_t texture,
                                                 const scene::TextureRecord& r) {
    const fs::path file = scene::texture_path(scene_dir, TextureId{texture});
    const std::string bytes = read_all(file);
    const auto layout = scene::parse_dds_layout(std::as_bytes(std::span(bytes.data(), bytes.size())), file.string());
    EXPECT_TRUE(layout.ok()) << (layout.ok() ? "" : layout.error().message);
    if (!layout.ok()) return {TexelFormat::kRgba8, false};
    const auto format = static_cast<TexelFormat>(r.format);
    return {layout->texel_format(), bytes.size() == scene::dds_file_bytes(format, r.width, r.height, r.mip_count)};
  }

  fs::path dir_;
  Model model_;
};

TEST(ImportTexelFormatFor, AutoIsBc1WhenOpaqueAndBc3WhenAlphaTestedAndAChosenFormatWins) {
  EXPECT_EQ(texel_format_for(std::nullopt, false), TexelFormat::kBc1);
  EXPECT_EQ(texel_format_for(std::nullopt, true), TexelFormat::kBc3);
  for (TexelFormat f : {TexelFormat::kBc1, TexelFormat::kBc3, TexelFormat::kRgba8})
    for (bool alpha_test : {false, true}) EXPECT_EQ(texel_format_for(f, alpha_test), f);
}

TEST_F(ImportFormats, AutoBakesOpaqueTexturesAsBc1AndCutOutsAsBc3AndTheManifestSaysMixed) {
  const auto report = import("scene", std::nullopt);
  ASSERT_TRUE(report.ok()) << report.error().message;
  const fs::path scene_dir = dir_ / "scene";
  const auto ids = texture_of_cases(scene_dir);
  const auto table = scene::read_texture_table(scene_dir);
  ASSERT_TRUE(table.ok()) << table.error().message;
  ASSERT_EQ(ids.size(), kCases.size());
  EXPECT_EQ(table->size(), kCases.size()) << "every case is a texture of its own";
  for (size_t i = 0; i < kCases.size(); ++i) {
    const scene::TextureRecord& r = (*table)[ids[i]];
    EXPECT_EQ(static_cast<TexelFormat>(r.format), kCases[i].auto_format) << kCases[i].name;
    const auto [header, length_ok] = dds_format(scene_dir, ids[i], r);
    EXPECT_EQ(header, kCases[i].auto_format) << kCases[i].name << ": the DDS header";
    EXPECT_TRUE(length_ok) << kCases[i].name << ": the file's length";
  }
  const auto path = [&](size_t c) { return scene::texture_path(scene_dir, TextureId{ids[c]}); };
  EXPECT_TRUE(fs::equivalent(path(0), path(1))) << "wrap-only twins share the baked file";
  EXPECT_TRUE(fs::equivalent(path(2), path(4))) << "MASK and BLEND at one cutoff share the baked file";
  EXPECT_FALSE(fs::equivalent(path(2), path(3))) << "one image opaque (BC1) and masked (BC3): two files";

  const auto manifest = scene::read_manifest(scene_dir);
  ASSERT_TRUE(manifest.ok()) << manifest.error().message;
  EXPECT_EQ(manifest->texture_format, std::nullopt);
  EXPECT_EQ(report->textures, kCases.size());
  EXPECT_TRUE(report->skipped.empty()) << report->skipped.front();
  EXPECT_EQ(report->images_baked, 3u) << "grid, leaf masked, leaf opaque; the twins are links";
  EXPECT_EQ((*table)[ids[0]].width, 16u);
  EXPECT_EQ(report->textures_by_format,
            (std::map<TexelFormat, uint64_t>{{TexelFormat::kBc1, 4}, {TexelFormat::kBc3, 3}}));
}

TEST_F(ImportFormats, AnExplicitFormatIsEveryTexturesAndTheManifests) {
  for (TexelFormat f : {TexelFormat::kBc1, TexelFormat::kBc3, TexelFormat::kRgba8}) {
    const std::string out(to_string(f));
    const auto report = import(out, f);
    ASSERT_TRUE(report.ok()) << report.error().message;
    const fs::path scene_dir = dir_ / out;
    const auto ids = texture_of_cases(scene_dir);
    const auto table = scene::read_texture_table(scene_dir);
    ASSERT_TRUE(table.ok()) << table.error().message;
    ASSERT_EQ(ids.size(), kCases.size());
    for (size_t i = 0; i < kCases.size(); ++i) {
      const scene::TextureRecord& r = (*table)[ids[i]];
      EXPECT_EQ(static_cast<TexelFormat>(r.format), f) << out << ": " << kCases[i].name;
      EXPECT_EQ(dds_format(scene_dir, ids[i], r), std::pair(f, true)) << out << ": " << kCases[i].name;
    }
    EXPECT_FALSE(fs::equivalent(scene::texture_path(scene_dir, TextureId{ids[2]}),
                                scene::texture_path(scene_dir, TextureId{ids[3]})))
        << out << ": the leaf opaque and masked differ in their alpha";
    const auto manifest = scene::read_manifest(scene_dir);
    ASSERT_TRUE(manifest.ok()) << manifest.error().message;
    EXPECT_EQ(manifest->texture_format, f) << out;
    EXPECT_EQ(report->textures_by_format, (std::map<TexelFormat, uint64_t>{{f, kCases.size()}})) << out;
  }
}

// So an auto scene draws what the bc1 and bc3 scenes draw, texture by texture.
TEST_F(ImportFormats, AutoWritesTheFilesTheOneFormatRunsWriteForEachTexture) {
  ASSERT_TRUE(import("auto", std::nullopt).ok());
  ASSERT_TRUE(import("bc1", TexelFormat::kBc1).ok());
  ASSERT_TRUE(import("bc3", TexelFormat::kBc3).ok());
  const auto ids = texture_of_cases(dir_ / "auto");
  ASSERT_EQ(ids.size(), kCases.size());
  for (size_t i = 0; i < kCases.size(); ++i) {
    const fs::path same_format = dir_ / std::string(to_string(kCases[i].auto_format));
    const auto other = texture_of_cases(same_format);
    ASSERT_EQ(other.size(), kCases.size());
    EXPECT_EQ(read_all(scene::texture_path(dir_ / "auto", TextureId{ids[i]})),
              read_all(scene::texture_path(same_format, TextureId{other[i]})))
        << kCases[i].name << ": auto and --format " << to_string(kCases[i].auto_format);
  }
}

TEST_F(ImportFormats, AutoWritesTheSameBytesTwiceAndOnOneOrTwoThreads) {
  ASSERT_TRUE(import("one", std::nullopt, 1).ok());
  ASSERT_TRUE(import("two", std::nullopt, 2).ok());
  ASSERT_TRUE(import("again", std::nullopt, 2).ok());
  const auto one = files_of(dir_ / "one"), two = files_of(dir_ / "two"), again = files_of(dir_ / "again");
  EXPECT_GT(one.size(), kCases.size()) << "the textures and the scene's own files";
  EXPECT_TRUE(one == two) << "1 thread and 2 threads must write identical files";
  EXPECT_TRUE(two == again) << "two runs must write identical files";
}

}  // namespace
}  // namespace texstream::import
