// The page file (common/page_file.hpp) and texstream-tile's baker (tools/tile): the quadtree's shape, every page's
// texels against an independently built pyramid, borders equal to the neighbours' texels (no seams under bilinear
// filtering), pages outside the image not stored, NoiseValues of known images, BC1 pages close to RGBA8 ones, and
// every damaged field of a file named in the error.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <squish.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <fstream>

#include "mip_chain.hpp"
#include "page_baker.hpp"
#include "test_temp_dir.hpp"
#include "texstream/common/page_file.hpp"

#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>

namespace texstream {
namespace {

using pages::PageFile;
using pages::PageGeometry;
using pages::PageId;
using pages::PageWrap;

// A source given as a function of the texel.
class FnSource final : public tile::PageSource {
 public:
  FnSource(uint32_t w, uint32_t h, std::function<uint32_t(uint32_t, uint32_t)> fn) : w_(w), h_(h), fn_(fn) {}
  Extent2D extent() const override { return {w_, h_}; }
  Status fill_rows(uint32_t y0, uint32_t rows, uint32_t* out) const override {
    for (uint32_t j = 0; j < rows; ++j)
      for (uint32_t x = 0; x < w_; ++x) out[uint64_t{j} * w_ + x] = fn_(x, y0 + j);
    return ok_status();
  }

 private:
  uint32_t w_, h_;
  std::function<uint32_t(uint32_t, uint32_t)> fn_;
};

std::vector<uint32_t> read_page(const std::filesystem::path& file, const PageFile& pf, PageId p) {
  const auto e = pf.entry(p);
  EXPECT_TRUE(e.has_value());
  std::vector<uint32_t> texels(e->bytes / 4);
  std::ifstream in(file, std::ios::binary);
  in.seekg(static_cast<std::streamoff>(e->offset));
  in.read(reinterpret_cast<char*>(texels.data()), e->bytes);
  return texels;
}

// The level below, written out here from the definition (linear-light 2x2 mean, reads past the edge clamped):
// the baker's pyramid is checked against it, not against itself.
std::vector<uint32_t> reference_down(const std::vector<uint32_t>& src, uint32_t w, uint32_t h) {
  const uint32_t dw = (w + 1) / 2, dh = (h + 1) / 2;
  std::vector<uint32_t> dst(uint64_t{dw} * dh);
  for (uint32_t y = 0; y < dh; ++y)
    for (uint32_t x = 0; x < dw; ++x) {
      uint32_t out = 0;
      for (int c = 0; c < 4; ++c) {
        float sum = 0;
        for (uint32_t dy = 0; dy < 2; ++dy)
          for (uint32_t dx = 0; dx < 2; ++dx) {
            const uint32_t sx = std::min(2 * x + dx, w - 1), sy = std::min(2 * y + dy, h - 1);
            const auto v = static_cast<uint8_t>(src[uint64_t{sy} * w + sx] >> (8 * c));
            sum += c == 3 ? static_cast<float>(v) : gen::srgb8_to_linear(v);
          }
        const uint32_t q = c == 3 ? static_cast<uint32_t>((sum + 2) / 4) : gen::linear_to_srgb8(sum / 4);
        out |= q << (8 * c);
      }
      dst[uint64_t{y} * dw + x] = out;
    }
  return dst;
}

uint32_t noisy(uint32_t x, uint32_t y) {
  uint32_t h = x * 73856093u ^ y * 19349663u;
  h ^= h >> 13;
  h *= 0x5bd1e995u;
  return (h & 0x00ffffffu) | 0xff000000u;
}

TEST(PageGeometry, ShapeOfTheQuadtree) {
  auto g = PageGeometry::make(TexelFormat::kRgba8, 300, 200, 64, 4, PageWrap::kClamp, "t");
  ASSERT_TRUE(g.ok()) << g.error().message;
  EXPECT_EQ(g->levels, 4u);  // 64 << 3 = 512 >= 300
  EXPECT_EQ(g->virtual_extent(), 512u);
  EXPECT_EQ(g->page_slots(), 1u + 4 + 16 + 64);
  EXPECT_EQ(g->image_extent(3), (Extent2D{300, 200}));
  EXPECT_EQ(g->image_extent(2), (Extent2D{150, 100}));
  EXPECT_EQ(g->image_extent(0), (Extent2D{38, 25}));
  EXPECT_EQ(g->pages_in_image(), 20u + 6 + 2 + 1);
  EXPECT_TRUE(g->in_image({3, 4, 3}));
  EXPECT_FALSE(g->in_image({3, 5, 0}));
  EXPECT_FALSE(g->in_image({3, 0, 4}));
  for (uint64_t s = 0; s < g->page_slots(); ++s) EXPECT_EQ(g->slot(g->page_of_slot(s)), s);
  EXPECT_EQ(g->slot({2, 1, 3}), 5u + 3 * 4 + 1);
  EXPECT_EQ(PageGeometry::levels_for(64, 64, 64), 1u);
  EXPECT_EQ(PageGeometry::levels_for(65, 1, 64), 2u);
}

TEST(PageGeometry, BadGeometriesAreNamed) {
  auto err = [](TexelFormat f, uint32_t w, uint32_t h, uint32_t p, uint32_t b, PageWrap wrap) {
    auto g = PageGeometry::make(f, w, h, p, b, wrap, "ground.tspages");
    EXPECT_FALSE(g.ok());
    return g.ok() ? std::string() : g.error().message;
  };
  EXPECT_NE(err(TexelFormat::kBc1, 100, 100, 64, 2, PageWrap::kClamp).find("border_texels 2"), std::string::npos);
  EXPECT_NE(err(TexelFormat::kRgba8, 100, 100, 48, 2, PageWrap::kClamp).find("page_texels 48"), std::string::npos);
  EXPECT_NE(err(TexelFormat::kRgba8, 100, 100, 64, 40, PageWrap::kClamp).find("border_texels 40"), std::string::npos);
  EXPECT_NE(err(TexelFormat::kRgba8, 300, 256, 64, 4, PageWrap::kRepeat).find("wrap repeat"), std::string::npos);
  EXPECT_NE(err(TexelFormat::kBc7, 100, 100, 64, 4, PageWrap::kClamp).find("bc7"), std::string::npos);
  EXPECT_NE(err(TexelFormat::kRgba8, 0, 100, 64, 4, PageWrap::kClamp).find("ground.tspages: extent"),
            std::string::npos);
}

// Every stored page's texels are its level's texels at the page's rectangle grown by the border (clamped at the
// image's edge), the levels being the reference pyramid; pages outside the image are not stored.
TEST(PageBake, PagesHoldTheirLevelsTexelsWithBorders) {
  const auto dir = test::fresh_test_dir("pages");
  const uint32_t w = 300, h = 200;
  FnSource src(w, h, noisy);
  tile::BakeOptions opt;
  opt.format = TexelFormat::kRgba8;
  opt.page_texels = 32;
  opt.border_texels = 4;
  opt.threads = 2;
  uint64_t last_done = 0, last_total = 0;
  auto st =
      tile::bake_pages(src, opt, dir / "t.tspages", [&](uint64_t d, uint64_t t) { last_done = d, last_total = t; });
  ASSERT_TRUE(st.ok()) << st.error().message;
  EXPECT_FALSE(std::filesystem::exists(dir / "t.tspages.partial"));
  auto pf = PageFile::open(dir / "t.tspages");
  ASSERT_TRUE(pf.ok()) << pf.error().message;
  const PageGeometry& g = pf->geometry();
  EXPECT_EQ(g.levels, 5u);
  EXPECT_EQ(pf->stored_pages(), g.pages_in_image());
  EXPECT_EQ(last_done, pf->stored_pages());
  EXPECT_EQ(last_total, pf->stored_pages());
  EXPECT_EQ(std::filesystem::file_size(dir / "t.tspages"), st->file_bytes);

  // The reference pyramid, finest last.
  std::vector<std::vector<uint32_t>> level(g.levels);
  std::vector<Extent2D> ext(g.levels);
  ext[g.levels - 1] = {w, h};
  level[g.levels - 1].resize(uint64_t{w} * h);
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x) level[g.levels - 1][uint64_t{y} * w + x] = noisy(x, y);
  for (uint32_t l = g.levels - 1; l > 0; --l) {
    level[l - 1] = reference_down(level[l], ext[l].width, ext[l].height);
    ext[l - 1] = {(ext[l].width + 1) / 2, (ext[l].height + 1) / 2};
    ASSERT_EQ(ext[l - 1], g.image_extent(l - 1));
  }

  const uint32_t side = g.stored_side();
  uint64_t checked = 0;
  for (uint32_t l = 0; l < g.levels; ++l) {
    const uint32_t n = 1u << l;
    for (uint32_t py = 0; py < n; ++py)
      for (uint32_t px = 0; px < n; ++px) {
        const PageId p{l, px, py};
        const bool inside = px * g.page_texels < ext[l].width && py * g.page_texels < ext[l].height;
        ASSERT_EQ(pf->stored(p), inside) << "level " << l << " page " << px << "," << py;
        if (!inside) continue;
        const auto texels = read_page(dir / "t.tspages", *pf, p);
        for (uint32_t j = 0; j < side; ++j)
          for (uint32_t i = 0; i < side; ++i) {
            const int64_t x =
                std::clamp<int64_t>(int64_t{px} * g.page_texels - g.border_texels + i, 0, ext[l].width - 1);
            const int64_t y =
                std::clamp<int64_t>(int64_t{py} * g.page_texels - g.border_texels + j, 0, ext[l].height - 1);
            ASSERT_EQ(texels[uint64_t{j} * side + i], level[l][static_cast<uint64_t>(y) * ext[l].width + x])
                << "level " << l << " page " << px << "," << py << " texel " << i << "," << j;
          }
        ++checked;
      }
  }
  EXPECT_EQ(checked, pf->stored_pages());
}

// Seams: a page's border column equals the texels its right neighbour holds there, so bilinear taps that reach
// into the border read what the whole texture holds (seed 004 §3.2.3.4).
TEST(PageBake, BordersRepeatTheNeighboursTexelsAndWrapForRepeatingTextures) {
  const auto dir = test::fresh_test_dir("pages");
  FnSource src(256, 256, noisy);
  tile::BakeOptions opt;
  opt.format = TexelFormat::kRgba8;
  opt.page_texels = 64;
  opt.border_texels = 4;
  opt.wrap = PageWrap::kRepeat;
  ASSERT_TRUE(tile::bake_pages(src, opt, dir / "r.tspages").ok());
  auto pf = PageFile::open(dir / "r.tspages");
  ASSERT_TRUE(pf.ok()) << pf.error().message;
  const uint32_t P = 64, B = 4, S = P + 2 * B;
  for (uint32_t l = 1; l < 3; ++l) {
    const uint32_t n = 1u << l;
    for (uint32_t py = 0; py < n; ++py)
      for (uint32_t px = 0; px < n; ++px) {
        const auto a = read_page(dir / "r.tspages", *pf, {l, px, py});
        const auto right = read_page(dir / "r.tspages", *pf, {l, (px + 1) % n, py});
        const auto below = read_page(dir / "r.tspages", *pf, {l, px, (py + 1) % n});
        for (uint32_t j = B; j < B + P; ++j)
          for (uint32_t b = 0; b < B; ++b) {
            // a's right border column b is right's interior column b; a's last interior column is right's left border.
            ASSERT_EQ(a[uint64_t{j} * S + B + P + b], right[uint64_t{j} * S + B + b]) << l << " " << px << "," << py;
            ASSERT_EQ(a[uint64_t{j} * S + P + b], right[uint64_t{j} * S + b]) << l << " " << px << "," << py;
            ASSERT_EQ(a[uint64_t{B + P + b} * S + j], below[uint64_t{B + b} * S + j]) << l << " " << px << "," << py;
          }
      }
  }
}

TEST(PageBake, NoiseValuesOfKnownImages) {
  const auto dir = test::fresh_test_dir("pages");
  tile::BakeOptions opt;
  opt.format = TexelFormat::kRgba8;
  opt.page_texels = 16;
  opt.border_texels = 0;
  // A flat colour changes nothing between levels, and the root equals its mean.
  FnSource flat(64, 64, [](uint32_t, uint32_t) { return 0xff336699u; });
  ASSERT_TRUE(tile::bake_pages(flat, opt, dir / "flat.tspages").ok());
  auto pf = PageFile::open(dir / "flat.tspages");
  ASSERT_TRUE(pf.ok());
  for (uint32_t l = 0; l < 3; ++l)
    for (uint32_t y = 0; y < (1u << l); ++y)
      for (uint32_t x = 0; x < (1u << l); ++x) EXPECT_EQ(pf->noise({l, x, y}), 0.0f);
  EXPECT_EQ(pf->mean_noise(), 0.0);
  // A one-texel checkerboard of black and white: the parent level is one grey, so each finest page differs from
  // its parent's quarter by half the white's luminance at every texel: 255 - grey on white, grey on black.
  FnSource checker(64, 64, [](uint32_t x, uint32_t y) { return (x + y) % 2 ? 0xffffffffu : 0xff000000u; });
  ASSERT_TRUE(tile::bake_pages(checker, opt, dir / "checker.tspages").ok());
  pf = PageFile::open(dir / "checker.tspages");
  ASSERT_TRUE(pf.ok());
  const double grey = gen::linear_to_srgb8(0.5f);  // the linear-light mean of black and white
  const double expected = std::sqrt(0.5 * (255 - grey) * (255 - grey) + 0.5 * grey * grey);
  EXPECT_NEAR(pf->noise({2, 1, 2}), expected, 0.5);
  EXPECT_NEAR(pf->noise({1, 0, 0}), 0.0, 1e-3);  // grey under grey
  EXPECT_NEAR(pf->noise({0, 0, 0}), 0.0, 1e-3);
  // 16 finest pages at `expected`, 4 + 1 coarser ones at 0.
  EXPECT_NEAR(pf->mean_noise(), expected * 16 / 21, 0.5);
  // A smooth ramp: refining it adds little.
  FnSource ramp(64, 64, [](uint32_t x, uint32_t) { return 0xff000000u | (x * 4) * 0x010101u; });
  ASSERT_TRUE(tile::bake_pages(ramp, opt, dir / "ramp.tspages").ok());
  pf = PageFile::open(dir / "ramp.tspages");
  ASSERT_TRUE(pf.ok());
  EXPECT_LT(pf->noise({2, 1, 1}), 2.0f);
  EXPECT_GT(pf->noise({0, 0, 0}), 50.0f);  // the root against its mean colour: the ramp's spread
}

// BC1 pages are the RGBA8 pages encoded: decoded they stay close to them (a painted ground, 8-texel borders).
TEST(PageBake, Bc1PagesDecodeCloseToTheRgba8Pages) {
  const auto dir = test::fresh_test_dir("pages");
  auto ground = tile::make_painted_ground(700, 520, 0.25, 3);
  tile::BakeOptions opt;
  opt.page_texels = 64;
  opt.border_texels = 8;
  opt.format = TexelFormat::kRgba8;
  ASSERT_TRUE(tile::bake_pages(*ground, opt, dir / "a.tspages").ok());
  opt.format = TexelFormat::kBc1;
  auto st = tile::bake_pages(*ground, opt, dir / "b.tspages");
  ASSERT_TRUE(st.ok()) << st.error().message;
  EXPECT_GT(st->mean_noise, 1.0);
  auto a = PageFile::open(dir / "a.tspages");
  auto b = PageFile::open(dir / "b.tspages");
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(b->geometry().page_bytes(), 80u * 80 / 2);
  double err = 0, n = 0;
  for (uint64_t s = 0; s < a->geometry().page_slots(); ++s) {
    const PageId p = a->geometry().page_of_slot(s);
    if (!a->stored(p)) continue;
    EXPECT_EQ(a->noise(p), b->noise(p));  // measured before encoding
    const auto ra = read_page(dir / "a.tspages", *a, p);
    const auto eb = b->entry(p);
    std::vector<uint8_t> blocks(eb->bytes);
    std::ifstream in(dir / "b.tspages", std::ios::binary);
    in.seekg(static_cast<std::streamoff>(eb->offset));
    in.read(reinterpret_cast<char*>(blocks.data()), eb->bytes);
    std::vector<uint32_t> rb(80 * 80);
    squish::DecompressImage(reinterpret_cast<squish::u8*>(rb.data()), 80, 80, blocks.data(), squish::kDxt1);
    for (size_t i = 0; i < ra.size(); ++i)
      for (int c = 0; c < 3; ++c) {
        const double d = double((ra[i] >> (8 * c)) & 0xff) - double((rb[i] >> (8 * c)) & 0xff);
        err += d * d;
        n += 1;
      }
  }
  const double psnr = 10 * std::log10(255.0 * 255.0 / (err / n));
  EXPECT_GT(psnr, 30.0) << "BC1 pages against RGBA8 pages";
}

TEST(PageBake, AnImageFileIsBakedAndAMissingOneIsNamed) {
  const auto dir = test::fresh_test_dir("pages");
  std::vector<uint32_t> img(90 * 70);
  for (uint32_t y = 0; y < 70; ++y)
    for (uint32_t x = 0; x < 90; ++x) img[y * 90 + x] = noisy(x, y);
  ASSERT_NE(stbi_write_png((dir / "in.png").c_str(), 90, 70, 4, img.data(), 90 * 4), 0);
  auto src = tile::open_image_source(dir / "in.png");
  ASSERT_TRUE(src.ok()) << src.error().message;
  EXPECT_EQ(src.value()->extent(), (Extent2D{90, 70}));
  std::vector<uint32_t> row(90);
  ASSERT_TRUE(src.value()->fill_rows(33, 1, row.data()).ok());
  EXPECT_EQ(row[17], noisy(17, 33));
  auto missing = tile::open_image_source(dir / "nope.png");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find("nope.png"), std::string::npos);
  // A bake into a folder that does not exist names the file and leaves nothing behind.
  tile::BakeOptions opt;
  auto st = tile::bake_pages(*src.value(), opt, dir / "no" / "such" / "x.tspages");
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("x.tspages"), std::string::npos);
}

// Every damaged field is refused with the file and the field named.
TEST(PageFileDamage, EachFieldIsNamed) {
  const auto dir = test::fresh_test_dir("pages");
  FnSource src(300, 200, noisy);
  tile::BakeOptions opt;
  opt.format = TexelFormat::kBc1;
  opt.page_texels = 64;
  ASSERT_TRUE(tile::bake_pages(src, opt, dir / "good.tspages").ok());
  std::vector<char> good(std::filesystem::file_size(dir / "good.tspages"));
  std::ifstream(dir / "good.tspages", std::ios::binary).read(good.data(), static_cast<std::streamsize>(good.size()));
  ASSERT_TRUE(PageFile::open(dir / "good.tspages").ok());

  auto damaged = [&](const std::string& name, auto&& edit, size_t keep_bytes = 0) {
    std::vector<char> bytes = good;
    edit(bytes);
    if (keep_bytes) bytes.resize(keep_bytes);
    const auto path = dir / (name + ".tspages");
    std::ofstream(path, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    auto pf = PageFile::open(path);
    EXPECT_FALSE(pf.ok()) << name;
    if (pf.ok()) return std::string();
    EXPECT_NE(pf.error().message.find(path.string()), std::string::npos) << pf.error().message;
    return pf.error().message;
  };
  auto put32 = [](std::vector<char>& b, size_t at, uint32_t v) { std::memcpy(b.data() + at, &v, 4); };
  auto put64 = [](std::vector<char>& b, size_t at, uint64_t v) { std::memcpy(b.data() + at, &v, 8); };
  const size_t hdr = sizeof(pages::PageFileHeader), entry = sizeof(pages::PageIndexEntry);
  EXPECT_NE(damaged("magic", [&](auto& b) { b[0] = 'X'; }).find("'magic'"), std::string::npos);
  EXPECT_NE(damaged("version", [&](auto& b) { put32(b, 8, 9); }).find("'version'"), std::string::npos);
  EXPECT_NE(damaged("format", [&](auto& b) { put32(b, 12, 77); }).find("'format'"), std::string::npos);
  EXPECT_NE(damaged("page", [&](auto& b) { put32(b, 24, 100); }).find("page_texels 100"), std::string::npos);
  EXPECT_NE(damaged("levels", [&](auto& b) { put32(b, 32, 7); }).find("'levels'"), std::string::npos);
  EXPECT_NE(damaged("data_offset", [&](auto& b) { put64(b, 56, 4096 * 9); }).find("'data_offset'"), std::string::npos);
  EXPECT_NE(damaged("stored", [&](auto& b) { put64(b, 40, 1000); }).find("'stored_pages'"), std::string::npos);
  EXPECT_NE(damaged(
                "short", [](auto&) {}, good.size() - 100)
                .find("too short"),
            std::string::npos);
  EXPECT_NE(damaged("offset", [&](auto& b) { put64(b, hdr + entry, uint64_t{1} << 40); }).find("'offset'"),
            std::string::npos);
  EXPECT_NE(damaged("bytes", [&](auto& b) { put32(b, hdr + entry + 8, 17); }).find("'bytes'"), std::string::npos);
  EXPECT_NE(damaged("noise", [&](auto& b) { put32(b, hdr + 2 * entry + 12, 0x7fc00000u); }).find("'noise'"),
            std::string::npos);
  EXPECT_NE(damaged("root", [&](auto& b) { put64(b, hdr, 0), put32(b, hdr + 8, 0); }).find("root"), std::string::npos);
  // A level-1 page dropped while its children stay: they have no ancestor to fall back on.
  EXPECT_NE(damaged("orphan", [&](auto& b) { put64(b, hdr + entry, 0), put32(b, hdr + entry + 8, 0); })
                .find("its parent is not"),
            std::string::npos);
  EXPECT_EQ(PageFile::open(dir / "absent.tspages").error().code, ErrorCode::kNotFound);
}

}  // namespace
}  // namespace texstream
