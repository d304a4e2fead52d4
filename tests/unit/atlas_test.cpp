// texstream-atlas on generated scenes: every mesh samples the same texels after packing as before (level 0 and
// level 1, decoded), the scene's files stay consistent, textures that repeat or are not a power of two are kept
// as they were, bad input is named, and the output does not depend on the thread count.
#include <gtest/gtest.h>
#include <squish.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <map>

#include "atlas_builder.hpp"
#include "scene_generator.hpp"
#include "texstream/common/dds.hpp"
#include "texstream/common/scene_format.hpp"

namespace fs = std::filesystem;
using namespace texstream;

namespace {

fs::path temp(const std::string& name) {
  const fs::path p = fs::temp_directory_path() / ("texstream_atlas_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(p);
  return p;
}

fs::path generated(const std::string& name, uint64_t textures, const std::string& format) {
  gen::GeneratorOptions o;
  o.out = temp(name);
  o.texture_count = textures;
  o.seed = 7;
  o.threads = 2;
  o.mixed_formats = format == "mixed";
  if (format != "mixed") o.format = *texel_format_from_string(format);
  EXPECT_TRUE(gen::generate_scene(o).ok());
  return o.out;
}

std::vector<uint8_t> slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Level `l` of texture `id`, decoded to RGBA8 (w x h at that level).
struct Level {
  uint32_t w = 0, h = 0;
  std::vector<uint32_t> texels;
  uint32_t at(double u, double v) const {
    const auto x = std::clamp(static_cast<int64_t>(std::floor(u * w)), int64_t{0}, int64_t{w} - 1);
    const auto y = std::clamp(static_cast<int64_t>(std::floor(v * h)), int64_t{0}, int64_t{h} - 1);
    return texels[static_cast<size_t>(y) * w + static_cast<size_t>(x)];
  }
};

Level level_of(const fs::path& dir, uint32_t id, const scene::TextureRecord& r, uint32_t l) {
  const auto bytes = slurp(scene::texture_path(dir, TextureId(id)));
  auto layout = scene::parse_dds_layout(std::as_bytes(std::span(bytes)), "test");
  EXPECT_TRUE(layout.ok());
  const auto f = static_cast<TexelFormat>(r.format);
  const Extent2D e = mip_extent(r.width, r.height, l);
  Level out{e.width, e.height, std::vector<uint32_t>(size_t{e.width} * e.height)};
  const uint8_t* src = bytes.data() + layout->mip_offset(l);
  if (f == TexelFormat::kRgba8) {
    std::memcpy(out.texels.data(), src, out.texels.size() * 4);
    return out;
  }
  const uint32_t bw = (e.width + 3) / 4, bb = f == TexelFormat::kBc1 ? 8 : 16;
  for (uint32_t by = 0; by < (e.height + 3) / 4; ++by)
    for (uint32_t bx = 0; bx < bw; ++bx) {
      squish::u8 rgba[64];
      squish::Decompress(rgba, src + (size_t{by} * bw + bx) * bb,
                         f == TexelFormat::kBc1 ? squish::kDxt1 : squish::kDxt5);
      for (uint32_t y = 0; y < 4 && 4 * by + y < e.height; ++y)
        for (uint32_t x = 0; x < 4 && 4 * bx + x < e.width; ++x)
          std::memcpy(&out.texels[size_t{4 * by + y} * e.width + 4 * bx + x], rgba + 4 * (4 * y + x), 4);
    }
  return out;
}

// Every triangle's centroid samples the same texel before and after, at level 0 and 1 (nearest texel: what
// the packing must not change; filtering across a packed texture's edge is the atlas's known cost).
void expect_same_texels(const fs::path& before, const fs::path& after, uint32_t atlas_px) {
  auto m0 = scene::read_meshes(before), m1 = scene::read_meshes(after);
  auto t0 = scene::read_texture_table(before), t1 = scene::read_texture_table(after);
  ASSERT_TRUE(m0.ok() && m1.ok() && t0.ok() && t1.ok());
  ASSERT_EQ(m0->meshes.size(), m1->meshes.size());
  std::map<std::pair<uint32_t, uint32_t>, Level> cache0, cache1;
  auto get = [](std::map<std::pair<uint32_t, uint32_t>, Level>& c, const fs::path& dir, uint32_t id,
                const scene::TextureRecord& r, uint32_t l) -> const Level& {
    auto it = c.find({id, l});
    if (it == c.end()) it = c.emplace(std::pair(id, l), level_of(dir, id, r, l)).first;
    return it->second;
  };
  uint64_t compared = 0, packed = 0;
  for (size_t i = 0; i < m0->meshes.size(); ++i) {
    const scene::MeshRecord &a = m0->meshes[i], &b = m1->meshes[i];
    ASSERT_EQ(a.index_count, b.index_count);
    ASSERT_LT(b.texture_id, t1->size());
    const scene::TextureRecord &ra = (*t0)[a.texture_id], &rb = (*t1)[b.texture_id];
    EXPECT_LE(std::max(rb.width, rb.height), std::max(atlas_px, std::max(ra.width, ra.height)));
    packed += rb.width != ra.width || rb.height != ra.height;
    for (uint32_t l = 0; l < 2; ++l) {
      if ((ra.width >> l) < 4 || (ra.height >> l) < 4) continue;
      const Level& la = get(cache0, before, a.texture_id, ra, l);
      const Level& lb = get(cache1, after, b.texture_id, rb, l);
      for (uint32_t k = 0; k + 2 < a.index_count; k += 3) {
        double ua = 0, va = 0, ub = 0, vb = 0;
        for (uint32_t c = 0; c < 3; ++c) {
          const scene::Vertex& x = m0->vertices[a.first_vertex + m0->indices[a.first_index + k + c]];
          const scene::Vertex& y = m1->vertices[b.first_vertex + m1->indices[b.first_index + k + c]];
          ua += static_cast<double>(x.uv[0]) / 3, va += static_cast<double>(x.uv[1]) / 3;
          ub += static_cast<double>(y.uv[0]) / 3, vb += static_cast<double>(y.uv[1]) / 3;
        }
        ASSERT_EQ(la.at(ua, va), lb.at(ub, vb)) << "mesh " << i << " level " << l << " triangle " << k / 3;
        ++compared;
      }
    }
  }
  EXPECT_GT(compared, 100u);
  EXPECT_GT(packed, m0->meshes.size() / 2) << "most meshes should have moved into an atlas";
}

}  // namespace

class AtlasFormats : public ::testing::TestWithParam<std::string> {};

TEST_P(AtlasFormats, EveryMeshSamplesTheSameTexelsFromItsAtlas) {
  const fs::path in = generated("in_" + GetParam(), 400, GetParam());
  atlas::AtlasOptions o;
  o.in = in;
  o.out = temp("out_" + GetParam());
  auto st = atlas::build_atlases(o);
  ASSERT_TRUE(st.ok()) << st.error().message;
  EXPECT_EQ(st->textures_in, 400u);
  EXPECT_GT(st->atlases, 10u);
  EXPECT_LT(st->textures_out, 200u);
  EXPECT_EQ(st->textures_packed + st->textures_kept, 400u);
  EXPECT_GT(static_cast<double>(st->texel_bytes_in) / static_cast<double>(st->atlas_bytes), 0.5) << "atlas fill";
  auto man = scene::read_manifest(o.out);
  ASSERT_TRUE(man.ok());
  EXPECT_EQ(man->texture_count, st->textures_out);
  EXPECT_EQ(man->texture_format, scene::read_manifest(in)->texture_format);
  ASSERT_TRUE(scene::read_colormap(o.out, st->textures_out).ok());
  expect_same_texels(in, o.out, o.atlas_px);
  fs::remove_all(in);
  fs::remove_all(o.out);
}

INSTANTIATE_TEST_SUITE_P(Atlas, AtlasFormats, ::testing::Values("bc1", "rgba8", "mixed"),
                         [](const auto& p) { return p.param; });

// A texture that repeats (sampling.bin) or is not a power of two cannot be packed without changing what it
// shows: it keeps its file, byte for byte, and its meshes their UVs.
TEST(Atlas, TexturesThatCannotBePackedAreKeptAsTheyWere) {
  const fs::path in = generated("keep_in", 200, "bc1");
  auto records = scene::read_texture_table(in);
  ASSERT_TRUE(records.ok());
  std::vector<uint32_t> sampling(records->size(), 0);
  sampling[3] = scene::make_sampling_flags(scene::TextureWrap::kRepeat, scene::TextureWrap::kClamp, false, 0);
  ASSERT_TRUE(scene::write_sampling(in, sampling).ok());
  atlas::AtlasOptions o;
  o.in = in;
  o.out = temp("keep_out");
  auto st = atlas::build_atlases(o);
  ASSERT_TRUE(st.ok()) << st.error().message;
  EXPECT_GE(st->kept_not_eligible, 1u);
  auto m0 = scene::read_meshes(in), m1 = scene::read_meshes(o.out);
  auto s1 = scene::map_sampling(o.out, st->textures_out);
  ASSERT_TRUE(m0.ok() && m1.ok() && s1.ok());
  for (size_t i = 0; i < m0->meshes.size(); ++i) {
    if (m0->meshes[i].texture_id != 3) continue;
    const uint32_t kept = m1->meshes[i].texture_id;
    EXPECT_EQ(s1->flags[kept], sampling[3]);
    EXPECT_EQ(slurp(scene::texture_path(o.out, TextureId(kept))), slurp(scene::texture_path(in, TextureId(3))));
    for (uint32_t v = 0; v < m0->meshes[i].vertex_count; ++v)
      EXPECT_EQ(m1->vertices[m1->meshes[i].first_vertex + v].uv[0], m0->vertices[m0->meshes[i].first_vertex + v].uv[0]);
  }
  fs::remove_all(in);
  fs::remove_all(o.out);
}

TEST(Atlas, BadOptionsAndFoldersAreNamed) {
  const fs::path in = generated("bad_in", 50, "bc1");
  atlas::AtlasOptions o;
  o.in = in;
  o.out = in;
  auto same = atlas::build_atlases(o);
  ASSERT_FALSE(same.ok());
  EXPECT_NE(same.error().message.find("--out"), std::string::npos);
  o.out = temp("bad_out");
  o.atlas_px = 500;
  auto odd = atlas::build_atlases(o);
  ASSERT_FALSE(odd.ok());
  EXPECT_NE(odd.error().message.find("500"), std::string::npos);
  o.atlas_px = 512;
  fs::create_directories(o.out);
  std::ofstream(o.out / "keep.txt") << "mine";
  auto busy = atlas::build_atlases(o);
  ASSERT_FALSE(busy.ok());
  EXPECT_NE(busy.error().message.find("--force"), std::string::npos);
  EXPECT_TRUE(fs::exists(o.out / "keep.txt")) << "nothing of a refused run is written";
  fs::remove(scene::texture_path(in, TextureId(5)));
  o.force = true;
  auto missing = atlas::build_atlases(o);
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find(scene::texture_path(in, TextureId(5)).filename().string()), std::string::npos)
      << missing.error().message;
  EXPECT_TRUE(fs::exists(o.out / "keep.txt")) << "a failed run leaves the old folder as it was";
  fs::remove_all(in);
  fs::remove_all(o.out);
}

TEST(Atlas, TheSameBytesOnOneOrTwoThreads) {
  const fs::path in = generated("det_in", 300, "mixed");
  std::vector<fs::path> outs;
  for (unsigned threads : {1u, 2u}) {
    atlas::AtlasOptions o;
    o.in = in;
    o.out = temp("det_out" + std::to_string(threads));
    o.threads = threads;
    ASSERT_TRUE(atlas::build_atlases(o).ok());
    outs.push_back(o.out);
  }
  size_t files = 0;
  for (const auto& e : fs::recursive_directory_iterator(outs[0])) {
    if (!e.is_regular_file()) continue;
    const fs::path rel = fs::relative(e.path(), outs[0]);
    ASSERT_EQ(slurp(e.path()), slurp(outs[1] / rel)) << rel;
    ++files;
  }
  EXPECT_GT(files, 20u);
  fs::remove_all(in);
  for (const auto& p : outs) fs::remove_all(p);
}
