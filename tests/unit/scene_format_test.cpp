// Scene format: every file round-trips, and every reader refuses truncated or corrupt input with an error that
// names the file (and the record). The DDS files we write must be readable by OpenImageIO.
#include <gtest/gtest.h>

#include <unistd.h>
#include <cstdio>

#include <OpenImageIO/imageio.h>
#include <cmath>
#include <cstring>
#include <fstream>

#include "test_temp_dir.hpp"
#include "texstream/common/scene_format.hpp"

namespace fs = std::filesystem;
using namespace texstream;
using namespace texstream::scene;

namespace {

class SceneFormatTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = test::fresh_test_dir("texstream_scene_format"); }
  void TearDown() override { fs::remove_all(dir_); }

  std::vector<char> read_all(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  }
  void write_all(const fs::path& p, const std::vector<char>& bytes) {
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }
  // Overwrites bytes at `offset` of a file with the raw bytes of `v`.
  template <class T>
  void patch(const fs::path& p, size_t offset, const T& v) {
    auto bytes = read_all(p);
    ASSERT_LE(offset + sizeof v, bytes.size());
    std::memcpy(bytes.data() + offset, &v, sizeof v);
    write_all(p, bytes);
  }

  fs::path dir_;
};

MeshData two_quads() {
  MeshData d;
  for (uint32_t m = 0; m < 2; ++m) {
    MeshRecord r{};
    r.origin[0] = 392000.5 + m;
    r.origin[1] = 5820000.25;
    r.origin[2] = 34.0;
    r.bounds_min[0] = 0;
    r.bounds_max[0] = 10;
    r.bounds_max[2] = 5;
    r.first_vertex = 4 * m;
    r.vertex_count = 4;
    r.first_index = 6 * m;
    r.index_count = 6;
    r.texture_id = m;
    d.meshes.push_back(r);
    const float xs[4] = {0, 10, 10, 0}, zs[4] = {0, 0, 5, 5};
    for (int v = 0; v < 4; ++v)
      d.vertices.push_back(Vertex{{xs[v], 0, zs[v]}, {0, -1, 0}, {xs[v] / 10, 1 - zs[v] / 5}});
    for (uint32_t i : {0u, 1u, 2u, 0u, 2u, 3u}) d.indices.push_back(i);
  }
  return d;
}

void expect_error_names(const Error& e, const std::string& needle) {
  EXPECT_NE(e.message.find(needle), std::string::npos) << "message: " << e.message;
}

// A read that must fail, with a message containing `needle`.
template <class R>
void expect_fails(const R& r, const std::string& needle) {
  ASSERT_FALSE(r.ok()) << "accepted input that should fail naming '" << needle << "'";
  expect_error_names(r.error(), needle);
}

}  // namespace

TEST_F(SceneFormatTest, ManifestRoundTrips) {
  Manifest m;
  m.name = "city";
  m.seed = 0xfeedbeefcafe1234ull;
  m.mesh_count = 12;
  m.texture_count = 11;
  m.texture_format = TexelFormat::kBc1;
  m.origin = {392000.125, 5820000.5, 0};
  m.bounds_min = {391000, 5819000, -1};
  m.bounds_max = {393000, 5821000, 150.75};
  ASSERT_TRUE(write_manifest(dir_, m).ok());
  auto r = read_manifest(dir_);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->name, m.name);
  EXPECT_EQ(r->seed, m.seed);
  EXPECT_EQ(r->mesh_count, 12u);
  EXPECT_EQ(r->texture_count, 11u);
  EXPECT_EQ(r->texture_format, TexelFormat::kBc1);
  EXPECT_EQ(r->origin, m.origin);
  EXPECT_EQ(r->bounds_min, m.bounds_min);
  EXPECT_EQ(r->bounds_max, m.bounds_max);
  EXPECT_EQ(r->camera_path, "camera_path.txt");
  EXPECT_FALSE(fs::exists(dir_ / "scene.json.tmp"));
}

TEST_F(SceneFormatTest, ManifestGroundPagesRoundTripAndBadOnesAreNamed) {
  Manifest m;
  m.name = "city";
  ASSERT_TRUE(write_manifest(dir_, m).ok());
  EXPECT_FALSE(read_manifest(dir_)->ground.has_value());
  m.ground = GroundPages{"pages/ground.tspages", {-512.5, -256, 0.25}, 0.125};
  ASSERT_TRUE(write_manifest(dir_, m).ok());
  auto r = read_manifest(dir_);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_TRUE(r->ground.has_value());
  EXPECT_EQ(r->ground->pages, "pages/ground.tspages");
  EXPECT_EQ(r->ground->origin, m.ground->origin);
  EXPECT_EQ(r->ground->metres_per_texel, 0.125);
  const std::pair<GroundPages, const char*> bad[] = {
      {{"../ground.tspages", {0, 0, 0}, 1}, "pages"},
      {{"/abs/ground.tspages", {0, 0, 0}, 1}, "pages"},
      {{"", {0, 0, 0}, 1}, "pages"},
      {{"g.tspages", {0, 0, 0}, 0}, "metres_per_texel"},
      {{"g.tspages", {0, 0, 0}, -2}, "metres_per_texel"},
  };
  for (const auto& [g, key] : bad) {
    m.ground = g;
    ASSERT_TRUE(write_manifest(dir_, m).ok());
    auto e = read_manifest(dir_);
    ASSERT_FALSE(e.ok()) << g.pages;
    expect_error_names(e.error(), "ground");
    expect_error_names(e.error(), key);
  }
}

TEST_F(SceneFormatTest, ManifestRejectsMissingWrongAndUnknown) {
  auto missing = read_manifest(dir_);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
  expect_error_names(missing.error(), "scene.json");

  const auto write_text = [&](const std::string& s) { std::ofstream(dir_ / "scene.json") << s; };
  write_text("{ not json");
  ASSERT_FALSE(read_manifest(dir_).ok());

  Manifest m;
  m.name = "x";
  ASSERT_TRUE(write_manifest(dir_, m).ok());
  auto text = read_all(dir_ / "scene.json");
  std::string s(text.begin(), text.end());

  std::string bad_format = s;
  bad_format.replace(bad_format.find("\"rgba8\""), 7, "\"astc\"");
  write_text(bad_format);
  auto e1 = read_manifest(dir_);
  ASSERT_FALSE(e1.ok());
  expect_error_names(e1.error(), "texture_format");

  std::string bad_version = s;
  bad_version.replace(bad_version.find("\"format_version\": 1"), 19, "\"format_version\": 7");
  write_text(bad_version);
  auto e2 = read_manifest(dir_);
  ASSERT_FALSE(e2.ok());
  EXPECT_EQ(e2.error().code, ErrorCode::kUnsupported);

  std::string no_seed = s;
  no_seed.replace(no_seed.find("\"seed\""), 6, "\"sead\"");
  write_text(no_seed);
  auto e3 = read_manifest(dir_);
  ASSERT_FALSE(e3.ok());
  expect_error_names(e3.error(), "'seed'");

  std::string negative = s;
  negative.replace(negative.find("\"texture_count\": 0"), 18, "\"texture_count\": -1");
  write_text(negative);
  auto e5 = read_manifest(dir_);
  ASSERT_FALSE(e5.ok());
  expect_error_names(e5.error(), "texture_count");

  std::string wrong_type = s;
  wrong_type.replace(wrong_type.find("\"mesh_count\": 0"), 15, "\"mesh_count\": \"a\"");
  write_text(wrong_type);
  auto e4 = read_manifest(dir_);
  ASSERT_FALSE(e4.ok());
  expect_error_names(e4.error(), "mesh_count");
}

TEST_F(SceneFormatTest, MeshesRoundTrip) {
  const MeshData d = two_quads();
  ASSERT_TRUE(write_meshes(dir_, d).ok());
  EXPECT_EQ(fs::file_size(dir_ / "meshes.bin"),
            sizeof(MeshFileHeader) + 2 * sizeof(MeshRecord) + 8 * sizeof(Vertex) + 12 * sizeof(uint32_t));
  auto r = read_meshes(dir_);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_EQ(r->meshes.size(), 2u);
  ASSERT_EQ(r->vertices.size(), 8u);
  ASSERT_EQ(r->indices.size(), 12u);
  EXPECT_EQ(0, std::memcmp(r->meshes.data(), d.meshes.data(), sizeof(MeshRecord) * 2));
  EXPECT_EQ(0, std::memcmp(r->vertices.data(), d.vertices.data(), sizeof(Vertex) * 8));
  EXPECT_EQ(r->indices, d.indices);
}

TEST_F(SceneFormatTest, MeshesRejectEveryTruncation) {
  ASSERT_TRUE(write_meshes(dir_, two_quads()).ok());
  const auto full = read_all(dir_ / "meshes.bin");
  for (size_t len = 0; len < full.size(); len += 7) {
    write_all(dir_ / "meshes.bin", std::vector<char>(full.begin(), full.begin() + static_cast<long>(len)));
    auto r = read_meshes(dir_);
    ASSERT_FALSE(r.ok()) << "accepted a file truncated to " << len << " bytes";
    expect_error_names(r.error(), "meshes.bin");
  }
  auto longer = full;
  longer.push_back(0);
  write_all(dir_ / "meshes.bin", longer);
  EXPECT_FALSE(read_meshes(dir_).ok());
}

TEST_F(SceneFormatTest, MeshesRejectCorruptHeaderAndRecords) {
  const fs::path p = dir_ / "meshes.bin";
  const auto write_fresh = [&] { ASSERT_TRUE(write_meshes(dir_, two_quads()).ok()); };
  const size_t rec1 = sizeof(MeshFileHeader) + sizeof(MeshRecord);

  write_fresh();
  patch(p, offsetof(MeshFileHeader, magic), uint64_t{0x1234});
  expect_fails(read_meshes(dir_), "magic");

  write_fresh();
  patch(p, offsetof(MeshFileHeader, version), uint32_t{2});
  expect_fails(read_meshes(dir_), "version");

  write_fresh();  // a huge count must not overflow the size check
  patch(p, offsetof(MeshFileHeader, vertex_count), uint64_t{1} << 62);
  expect_fails(read_meshes(dir_), "counts exceed");

  write_fresh();  // mesh 1's vertex range runs past the array
  patch(p, rec1 + offsetof(MeshRecord, first_vertex), uint32_t{6});
  expect_fails(read_meshes(dir_), "mesh 1");

  write_fresh();
  patch(p, rec1 + offsetof(MeshRecord, first_index), uint32_t{0xffffffffu});
  expect_fails(read_meshes(dir_), "mesh 1");

  write_fresh();
  patch(p, rec1 + offsetof(MeshRecord, index_count), uint32_t{5});
  expect_fails(read_meshes(dir_), "triangles");

  write_fresh();  // an index beyond the mesh's own vertices
  patch(p, sizeof(MeshFileHeader) + 2 * sizeof(MeshRecord) + 8 * sizeof(Vertex) + 7 * sizeof(uint32_t), uint32_t{4});
  expect_fails(read_meshes(dir_), "mesh 1");

  write_fresh();
  patch(p, rec1 + offsetof(MeshRecord, origin), std::numeric_limits<double>::quiet_NaN());
  expect_fails(read_meshes(dir_), "not finite");
}

TEST_F(SceneFormatTest, TextureTableRoundTripsAndValidates) {
  const std::vector<TextureRecord> t = {{4, 512, full_mip_count(4, 512), 2}, {256, 128, 9, 2}, {1, 1, 1, 1}};
  ASSERT_TRUE(write_texture_table(dir_, t).ok());
  auto r = read_texture_table(dir_);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_EQ(r->size(), 3u);
  EXPECT_EQ(0, std::memcmp(r->data(), t.data(), sizeof(TextureRecord) * 3));

  const fs::path p = dir_ / "textures.bin";
  const size_t rec1 = sizeof(TextureFileHeader) + sizeof(TextureRecord);
  const auto expect_rejected = [&](size_t offset, uint32_t value, const std::string& needle) {
    ASSERT_TRUE(write_texture_table(dir_, t).ok());
    patch(p, offset, value);
    auto bad = read_texture_table(dir_);
    ASSERT_FALSE(bad.ok()) << needle;
    expect_error_names(bad.error(), needle);
  };
  expect_rejected(rec1 + offsetof(TextureRecord, mip_count), 8, "texture 1");
  expect_rejected(rec1 + offsetof(TextureRecord, width), 0, "texture 1");
  expect_rejected(rec1 + offsetof(TextureRecord, height), kMaxTextureExtent + 1, "texture 1");
  expect_rejected(rec1 + offsetof(TextureRecord, format), 9, "unknown format");
  expect_rejected(offsetof(TextureFileHeader, magic), 7, "magic");
  expect_rejected(offsetof(TextureFileHeader, texture_count), 4, "textures.bin");

  ASSERT_TRUE(write_texture_table(dir_, t).ok());
  const auto full = read_all(p);
  for (size_t len = 0; len < full.size(); ++len) {
    write_all(p, std::vector<char>(full.begin(), full.begin() + static_cast<long>(len)));
    ASSERT_FALSE(read_texture_table(dir_).ok()) << len;
  }
}

TEST_F(SceneFormatTest, ColormapRoundTripsAndValidates) {
  const std::vector<uint32_t> c = {0xff102030u, 0xff405060u, 0x80ffffffu};
  ASSERT_TRUE(write_colormap(dir_, c).ok());
  auto r = read_colormap(dir_, 3);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(*r, c);
  auto wrong_count = read_colormap(dir_, 4);
  ASSERT_FALSE(wrong_count.ok());
  expect_error_names(wrong_count.error(), "colormap.bin");

  const auto full = read_all(dir_ / "colormap.bin");
  for (size_t len = 0; len < full.size(); ++len) {
    write_all(dir_ / "colormap.bin", std::vector<char>(full.begin(), full.begin() + static_cast<long>(len)));
    ASSERT_FALSE(read_colormap(dir_, 3).ok()) << len;
  }
  auto missing = read_colormap(dir_ / "nope", 3);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
}

TEST_F(SceneFormatTest, SamplingRoundTripsAndRefusesUnknownModesNamingTheTexture) {
  const std::vector<uint32_t> f = {make_sampling_flags(TextureWrap::kRepeat, TextureWrap::kMirror, false, 128),
                                   make_sampling_flags(TextureWrap::kClamp, TextureWrap::kClamp, true, 100), 0};
  ASSERT_TRUE(write_sampling(dir_, f).ok());
  auto r = map_sampling(dir_, 3);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(std::vector<uint32_t>(r->flags.begin(), r->flags.end()), f);
  EXPECT_EQ(f[0] & 3u, 1u);
  EXPECT_EQ((f[0] >> 2) & 3u, 2u);
  EXPECT_EQ((f[1] >> 8) & 0xffu, 100u);
  expect_error_names(map_sampling(dir_, 4).error(), "sampling.bin");
  const std::vector<uint32_t> bad = {0, 3u << 2};  // wrap mode 3 along v
  ASSERT_TRUE(write_sampling(dir_, bad).ok());
  auto refused = map_sampling(dir_, 2);
  ASSERT_FALSE(refused.ok());
  expect_error_names(refused.error(), "texture 1");
  EXPECT_EQ(map_sampling(dir_ / "nope", 2).error().code, ErrorCode::kNotFound);
}

TEST_F(SceneFormatTest, TransformsRoundTripAndRefuseWhatIsNotARotationWithAScale) {
  const float h = std::sqrt(0.5f);
  std::vector<MeshTransform> t = {kIdentityTransform, {{0, 0, h, h}, 2.5f}};
  ASSERT_TRUE(write_transforms(dir_, t).ok());
  auto r = map_transforms(dir_, 2);
  ASSERT_TRUE(r.ok()) << r.error().message;
  ASSERT_EQ(r->transforms.size(), 2u);
  EXPECT_EQ(r->transforms[1].scale, 2.5f);
  EXPECT_EQ(r->transforms[1].rotation[3], h);
  expect_error_names(map_transforms(dir_, 3).error(), "transforms.bin");
  for (const MeshTransform& wrong : {MeshTransform{{0, 0, 0, 2}, 1}, MeshTransform{{0, 0, 0, 1}, 0},
                                     MeshTransform{{0, 0, 0, 1}, -1}, MeshTransform{{0, 0, NAN, 1}, 1}}) {
    t[1] = wrong;
    ASSERT_TRUE(write_transforms(dir_, t).ok());
    auto refused = map_transforms(dir_, 2);
    ASSERT_FALSE(refused.ok());
    expect_error_names(refused.error(), "mesh 1");
  }
  const auto full = read_all(dir_ / "transforms.bin");
  for (size_t len = 0; len < full.size(); len += 7) {
    write_all(dir_ / "transforms.bin", std::vector<char>(full.begin(), full.begin() + static_cast<long>(len)));
    ASSERT_FALSE(map_transforms(dir_, 2).ok()) << len;
  }
  EXPECT_EQ(map_transforms(dir_ / "nope", 2).error().code, ErrorCode::kNotFound);
}

TEST(TexturePath, SplitsIdIntoFolderAndFile) {
  EXPECT_EQ(texture_path("/s", TextureId{0}), fs::path("/s/textures/000/00000000.dds"));
  EXPECT_EQ(texture_path("/s", TextureId{0x12345}), fs::path("/s/textures/012/00012345.dds"));
  EXPECT_EQ(texture_path("/s", TextureId{0xffffffffu}), fs::path("/s/textures/fff/ffffffff.dds"));
}

// texture_path builds its text directly: it must equal what path appends give, for any folder spelling.
TEST(TexturePath, EqualsThePathAppendsForEveryFolderSpelling) {
  for (const char* dir : {"", "/s", "/s/", "rel/dir", ".", "/a b/c.d", "//x//"}) {
    for (uint32_t id : {0u, 1u, 0xfffu, 0x1000u, 0x1234u, 0xabcdefu, 0x7fffffffu, 0xffffffffu}) {
      char folder[8];
      char file[16];
      std::snprintf(folder, sizeof folder, "%03x", (id >> 12) & 0xfffu);
      std::snprintf(file, sizeof file, "%08x.dds", id);
      const fs::path want = fs::path(dir) / "textures" / folder / file;
      EXPECT_EQ(texture_path(dir, TextureId{id}).native(), want.native()) << "dir '" << dir << "' id " << id;
    }
  }
}

TEST(DdsHeader, RoundTripsEveryFormat) {
  for (TexelFormat f : {TexelFormat::kRgba8, TexelFormat::kBc1, TexelFormat::kBc3}) {
    const auto h = make_dds_header(f, 512, 8, 10);
    auto info = parse_dds_layout(h, "t.dds");
    ASSERT_TRUE(info.ok()) << info.error().message;
    EXPECT_EQ(info->encoding, f == TexelFormat::kBc1   ? DdsEncoding::kBc1
                              : f == TexelFormat::kBc3 ? DdsEncoding::kBc3
                                                       : DdsEncoding::kRgba8);
    EXPECT_EQ(info->texel_format(), f);
    // Level 1 of 256x4 starts after level 0: BC3 16 bytes per block (128 x 2 blocks), BC1 8, RGBA8 4 per texel.
    EXPECT_EQ(info->mip_offset(1), kDdsHeaderBytes + (f == TexelFormat::kBc3   ? 4096u
                                                      : f == TexelFormat::kBc1 ? 2048u
                                                                               : 16384u));
    EXPECT_EQ(info->width, 512u);
    EXPECT_EQ(info->height, 8u);
    EXPECT_EQ(info->mip_count, 10u);
    EXPECT_EQ(info->data_offset, kDdsHeaderBytes);
  }
}

// Damaged headers are refused; a pixel format that cannot be served raw parses as kOther (decoded, not cut).
TEST(DdsHeader, RejectsWhatWeCannotServe) {
  const auto good = make_dds_header(TexelFormat::kRgba8, 64, 32, 7);
  const auto with_word = [&](size_t word, uint32_t value) {
    auto h = good;
    std::memcpy(h.data() + 4 * word, &value, 4);
    return h;
  };
  EXPECT_FALSE(parse_dds_layout(std::span(good).first(127), "a.dds").ok());
  expect_fails(parse_dds_layout(with_word(0, 0x12345678), "a.dds"), "a.dds");
  EXPECT_FALSE(parse_dds_layout(with_word(1, 100), "a.dds").ok());          // header size
  EXPECT_FALSE(parse_dds_layout(with_word(3, 0), "a.dds").ok());            // height 0
  EXPECT_FALSE(parse_dds_layout(with_word(4, 40000), "a.dds").ok());        // width > 32768
  EXPECT_FALSE(parse_dds_layout(with_word(7, 8), "a.dds").ok());            // 8 mips for 64x32
  const auto bgra = parse_dds_layout(with_word(23, 0x00ff0000u), "a.dds");  // BGRA masks
  ASSERT_TRUE(bgra.ok()) << bgra.error().message;
  EXPECT_EQ(bgra->encoding, DdsEncoding::kOther);
  auto dx10 = with_word(20, 0x4);
  const uint32_t fourcc = 0x30315844;
  std::memcpy(dx10.data() + 4 * 21, &fourcc, 4);
  expect_fails(parse_dds_layout(dx10, "a.dds"), "DX10");  // the 128 bytes end inside the DX10 extension
}

// Writes a DDS with known texels at every mip and checks that OpenImageIO reads the same extents and texels.
TEST_F(SceneFormatTest, OpenImageIoReadsOurRgba8Dds) {
  const uint32_t w = 16, h = 4, mips = full_mip_count(w, h);
  const fs::path p = dir_ / "t.dds";
  {
    std::ofstream out(p, std::ios::binary);
    const auto hdr = make_dds_header(TexelFormat::kRgba8, w, h, mips);
    out.write(reinterpret_cast<const char*>(hdr.data()), hdr.size());
    for (uint32_t l = 0; l < mips; ++l) {
      const Extent2D e = mip_extent(w, h, l);
      for (uint32_t y = 0; y < e.height; ++y)
        for (uint32_t x = 0; x < e.width; ++x) {
          const uint8_t px[4] = {static_cast<uint8_t>(x * 10), static_cast<uint8_t>(y * 40),
                                 static_cast<uint8_t>(l * 50), 255};
          out.write(reinterpret_cast<const char*>(px), 4);
        }
    }
  }
  ASSERT_EQ(fs::file_size(p), dds_file_bytes(TexelFormat::kRgba8, w, h, mips));
  auto in = OIIO::ImageInput::open(p.string());
  ASSERT_TRUE(in) << OIIO::geterror();
  for (uint32_t l = 0; l < mips; ++l) {
    ASSERT_TRUE(in->seek_subimage(0, static_cast<int>(l))) << "mip " << l << ": " << in->geterror();
    const OIIO::ImageSpec& spec = in->spec();
    const Extent2D e = mip_extent(w, h, l);
    ASSERT_EQ(spec.width, static_cast<int>(e.width));
    ASSERT_EQ(spec.height, static_cast<int>(e.height));
    ASSERT_EQ(spec.nchannels, 4);
    std::vector<uint8_t> px(size_t{e.width} * e.height * 4);
    ASSERT_TRUE(in->read_image(0, static_cast<int>(l), 0, 4, OIIO::TypeDesc::UINT8, px.data())) << in->geterror();
    for (uint32_t y = 0; y < e.height; ++y)
      for (uint32_t x = 0; x < e.width; ++x) {
        const uint8_t* q = &px[(size_t{y} * e.width + x) * 4];
        EXPECT_EQ(q[0], x * 10);
        EXPECT_EQ(q[1], y * 40);
        EXPECT_EQ(q[2], l * 50);
        EXPECT_EQ(q[3], 255);
      }
  }
  EXPECT_FALSE(in->seek_subimage(0, static_cast<int>(mips)));
}

TEST_F(SceneFormatTest, OpenImageIoReadsOurBc1Dds) {
  const uint32_t w = 8, h = 32, mips = full_mip_count(w, h);
  const fs::path p = dir_ / "t.dds";
  {
    std::ofstream out(p, std::ios::binary);
    const auto hdr = make_dds_header(TexelFormat::kBc1, w, h, mips);
    out.write(reinterpret_cast<const char*>(hdr.data()), hdr.size());
    // Every block: both endpoints pure red in RGB565 and all indices 0 -> every texel decodes to (255, 0, 0).
    const uint8_t block[8] = {0x00, 0xf8, 0x00, 0xf8, 0, 0, 0, 0};
    for (uint32_t l = 0; l < mips; ++l)
      for (uint64_t b = 0; b < mip_bytes(TexelFormat::kBc1, w, h, l) / 8; ++b)
        out.write(reinterpret_cast<const char*>(block), 8);
  }
  ASSERT_EQ(fs::file_size(p), dds_file_bytes(TexelFormat::kBc1, w, h, mips));
  auto in = OIIO::ImageInput::open(p.string());
  ASSERT_TRUE(in) << OIIO::geterror();
  EXPECT_EQ(in->spec().get_string_attribute("compression"), "DXT1");
  for (uint32_t l = 0; l < mips; ++l) {
    ASSERT_TRUE(in->seek_subimage(0, static_cast<int>(l))) << "mip " << l;
    const Extent2D e = mip_extent(w, h, l);
    ASSERT_EQ(in->spec().width, static_cast<int>(e.width));
    ASSERT_EQ(in->spec().height, static_cast<int>(e.height));
    std::vector<uint8_t> px(size_t{e.width} * e.height * static_cast<size_t>(in->spec().nchannels));
    ASSERT_TRUE(in->read_image(0, static_cast<int>(l), 0, in->spec().nchannels, OIIO::TypeDesc::UINT8, px.data()))
        << in->geterror();
    EXPECT_EQ(px[0], 255);
    EXPECT_EQ(px[1], 0);
    EXPECT_EQ(px[2], 0);
  }
}
