// Pure parts of the format support: DDS layouts from other tools, texel conversion to RGBA8, the file
// lookup order, and the latency histogram.
#include <gtest/gtest.h>

#include <array>
#include <cstring>
#include <limits>
#include <vector>

#include "texstream/common/dds.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/server/decode/texel_conversion.hpp"
#include "texstream/server/load/server_stats.hpp"
#include "texstream/server/load/texture_file_index.hpp"

namespace texstream::server {
namespace {

// A DDS header as a third-party tool writes it; `dx10` adds the DX10 extension with `dxgi`.
std::vector<std::byte> dds_header(uint32_t w, uint32_t h, uint32_t mips, uint32_t fourcc, bool dx10 = false,
                                  uint32_t dxgi = 0) {
  std::array<uint32_t, 37> words{};
  words[0] = 0x20534444u;  // "DDS "
  words[1] = 124;
  words[2] = 0x1 | 0x2 | 0x4 | 0x1000 | (mips > 0 ? 0x20000u : 0u);
  words[3] = h;
  words[4] = w;
  words[7] = mips;
  words[19] = 32;
  words[20] = 0x4;  // FourCC
  words[21] = fourcc;
  words[27] = 0x1000;
  if (dx10) {
    words[32] = dxgi;
    words[33] = 3;  // TEXTURE2D
    words[35] = 1;  // array size
  }
  std::vector<std::byte> out(dx10 ? 148 : 128);
  std::memcpy(out.data(), words.data(), out.size());
  return out;
}

constexpr uint32_t kDxt1 = 0x31545844u, kDx10 = 0x30315844u, kDxt5 = 0x35545844u;

TEST(DdsLayoutTest, GeneratorHeaderIsRawWithMipsAfter128Bytes) {
  for (TexelFormat f : {TexelFormat::kRgba8, TexelFormat::kBc1}) {
    const auto h = scene::make_dds_header(f, 64, 32, full_mip_count(64, 32));
    auto l = scene::parse_dds_layout(h, "gen.dds");
    ASSERT_TRUE(l.ok()) << l.error().message;
    EXPECT_EQ(l->encoding, f == TexelFormat::kBc1 ? scene::DdsEncoding::kBc1 : scene::DdsEncoding::kRgba8);
    EXPECT_EQ(l->mip_count, 7u);
    for (uint32_t m = 0; m < 7; ++m) EXPECT_EQ(l->mip_offset(m), scene::dds_mip_offset(f, 64, 32, m));
  }
}

TEST(DdsLayoutTest, Dx10Bc1DataStartsAfter148Bytes) {
  const auto h = dds_header(16, 16, 5, kDx10, true, 71);
  auto l = scene::parse_dds_layout(h, "dx10.dds");
  ASSERT_TRUE(l.ok()) << l.error().message;
  EXPECT_EQ(l->encoding, scene::DdsEncoding::kBc1);
  EXPECT_EQ(l->mip_offset(0), 148u);
  EXPECT_EQ(l->mip_offset(1), 148u + 128u);  // 16x16 BC1 = 16 blocks of 8 bytes
  EXPECT_EQ(l->mip_size(4), 8u);             // 1x1 is one block
}

TEST(DdsLayoutTest, Dxt5IsBc3AndOtherEncodingsAreForOpenImageIOAndNoMipCountMeansOne) {
  auto dxt5 = scene::parse_dds_layout(dds_header(8, 8, 0, kDxt5), "dxt5.dds");
  ASSERT_TRUE(dxt5.ok());
  EXPECT_EQ(dxt5->encoding, scene::DdsEncoding::kBc3);  // served raw to a bc3 texture, decoded for an rgba8 one
  EXPECT_EQ(dxt5->mip_size(0), 64u);                    // 8x8: 4 blocks of 16 bytes
  EXPECT_EQ(dxt5->mip_count, 1u);
  auto bc7 = scene::parse_dds_layout(dds_header(8, 8, 0, kDx10, true, 98), "bc7.dds");  // DXGI_FORMAT_BC7_UNORM
  ASSERT_TRUE(bc7.ok());
  EXPECT_EQ(bc7->encoding, scene::DdsEncoding::kBc7);
  EXPECT_EQ(bc7->mip_offset(0), 148u);
  EXPECT_EQ(bc7->mip_size(0), 64u);
  auto bc5 = scene::parse_dds_layout(dds_header(8, 8, 0, kDx10, true, 83), "bc5.dds");  // DXGI_FORMAT_BC5_UNORM
  ASSERT_TRUE(bc5.ok());
  EXPECT_EQ(bc5->encoding, scene::DdsEncoding::kOther);
  auto dxt1 = scene::parse_dds_layout(dds_header(8, 8, 2, kDxt1), "short-chain.dds");
  ASSERT_TRUE(dxt1.ok());
  EXPECT_EQ(dxt1->mip_count, 2u);
}

TEST(DdsLayoutTest, HostileHeadersAreCorruptNamingThePath) {
  auto h = dds_header(8, 8, 9, kDxt1);  // 9 mips for 8x8 (4 at most)
  auto r = scene::parse_dds_layout(h, "bad.dds");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(r.error().message.find("bad.dds"), std::string::npos);
  EXPECT_FALSE(scene::parse_dds_layout(dds_header(0, 8, 1, kDxt1), "zero.dds").ok());
  EXPECT_FALSE(scene::parse_dds_layout(dds_header(1u << 20, 8, 1, kDxt1), "huge.dds").ok());
  const auto legacy = dds_header(8, 8, 1, kDxt1);
  EXPECT_FALSE(scene::parse_dds_layout(std::span(legacy).first(100), "short.dds").ok());
  const auto dx10 = dds_header(8, 8, 1, kDx10, true, 71);
  EXPECT_FALSE(scene::parse_dds_layout(std::span(dx10).first(140), "dx10cut.dds").ok());
  auto cube = dds_header(8, 8, 1, kDxt1);
  cube[112] = std::byte{0x00};
  cube[113] = std::byte{0x02};  // caps2 cubemap
  EXPECT_FALSE(scene::parse_dds_layout(cube, "cube.dds").ok());
  auto arr = dds_header(8, 8, 1, kDx10, true, 71);
  arr[140] = std::byte{6};  // array of 6
  EXPECT_FALSE(scene::parse_dds_layout(arr, "array.dds").ok());
}

TEST(TexelConversionTest, ChannelCountsExpandToRgba8) {
  const uint8_t grey[] = {10, 20};
  std::byte out[8];
  channels_u8_to_rgba8(grey, 1, 2, out);
  EXPECT_EQ(std::to_integer<int>(out[0]), 10);
  EXPECT_EQ(std::to_integer<int>(out[2]), 10);
  EXPECT_EQ(std::to_integer<int>(out[3]), 255);
  EXPECT_EQ(std::to_integer<int>(out[4]), 20);
  const uint8_t ga[] = {7, 99};
  channels_u8_to_rgba8(ga, 2, 1, out);
  EXPECT_EQ(std::to_integer<int>(out[1]), 7);
  EXPECT_EQ(std::to_integer<int>(out[3]), 99);
  const uint8_t rgb[] = {1, 2, 3};
  channels_u8_to_rgba8(rgb, 3, 1, out);
  EXPECT_EQ(std::to_integer<int>(out[2]), 3);
  EXPECT_EQ(std::to_integer<int>(out[3]), 255);
  const uint8_t rgba[] = {1, 2, 3, 4};
  channels_u8_to_rgba8(rgba, 4, 1, out);
  EXPECT_EQ(std::to_integer<int>(out[3]), 4);
}

TEST(TexelConversionTest, LinearFloatIsSrgbEncodedAndAlphaStaysLinear) {
  EXPECT_EQ(linear_to_srgb8(0.0f), 0);
  EXPECT_EQ(linear_to_srgb8(1.0f), 255);
  EXPECT_EQ(linear_to_srgb8(0.5f), 188);  // sRGB(0.5) = 0.7354
  EXPECT_EQ(linear_to_srgb8(0.001f), 3);  // linear segment: 12.92 * 0.001 * 255 = 3.3
  EXPECT_EQ(linear_to_srgb8(-1.0f), 0);
  EXPECT_EQ(linear_to_srgb8(7.0f), 255);
  const float px[] = {0.5f, 0.5f, 0.5f, 0.5f, std::numeric_limits<float>::quiet_NaN(), 0, 0, 1};
  std::byte out[8];
  channels_linear_float_to_rgba8(px, 4, 2, out);
  EXPECT_EQ(std::to_integer<int>(out[0]), 188);
  EXPECT_EQ(std::to_integer<int>(out[3]), 128);  // alpha 0.5 linear
  EXPECT_EQ(std::to_integer<int>(out[4]), 0);    // NaN
}

// texture_file_path() / texture_file_path_text() build their text by hand (no path appends): it must name exactly the
// file scene::texture_path() names, with the kind's suffix, for any scene folder spelling and any id.
TEST(TextureFileIndexTest, FilePathIsTheSceneTexturePathWithTheKindsSuffix) {
  for (const char* dir : {"", "/s", "/s/", "rel/dir", ".", "/a b/c.d", "//x//"}) {
    for (uint32_t id : {0u, 1u, 0xfffu, 0x1000u, 0x1234u, 0xabcdefu, 0x7fffffffu, 0xffffffffu}) {
      for (TextureFileKind kind : kTextureFileKinds) {
        std::filesystem::path want = scene::texture_path(dir, TextureId(id));
        want.replace_extension(suffix_of(kind));
        const std::filesystem::path got = texture_file_path(dir, TextureId(id), kind);
        EXPECT_EQ(got.native(), want.native()) << "dir '" << dir << "' id " << id;
        // The text the loader opens (Storage::open_text) is the same name.
        EXPECT_EQ(texture_file_path_text(dir, TextureId(id), kind), want.native()) << "dir '" << dir << "' id " << id;
        EXPECT_EQ(got, want);
        EXPECT_EQ(got.extension().string(), suffix_of(kind));
      }
    }
  }
}

TEST(TextureFileIndexTest, SuffixesInLookupOrderAndRememberedEntries) {
  ASSERT_EQ(kTextureFileKinds.front(), TextureFileKind::kDds);
  EXPECT_EQ(texture_file_path("/s", TextureId(0x1234), TextureFileKind::kTx).string(), "/s/textures/001/00001234.tx");
  EXPECT_EQ(texture_file_path("/s", TextureId(0x1234), TextureFileKind::kExr).extension(), ".exr");
  TextureFileIndex index;
  EXPECT_FALSE(index.find(TextureId(5)));
  index.remember(TextureId(5), {TextureFileKind::kTif, std::nullopt});
  ASSERT_TRUE(index.find(TextureId(5)));
  EXPECT_EQ(index.find(TextureId(5))->kind, TextureFileKind::kTif);
  // Same slot, other texture: replaces, never answers for the wrong id.
  index.remember(TextureId(5 + TextureFileIndex::kEntries), {TextureFileKind::kExr, std::nullopt});
  EXPECT_FALSE(index.find(TextureId(5)));
  index.forget(TextureId(5 + TextureFileIndex::kEntries));
  EXPECT_FALSE(index.find(TextureId(5 + TextureFileIndex::kEntries)));
}

TEST(LatencyHistogramTest, PercentilesAreWithinABucket) {
  LatencyHistogram h;
  for (uint64_t v = 1; v <= 1000; ++v) h.record(v);
  EXPECT_EQ(h.count(), 1000u);
  EXPECT_EQ(h.max(), 1000u);
  EXPECT_NEAR(h.mean(), 500.5, 1e-9);
  const double p50 = h.percentile(50), p99 = h.percentile(99);
  EXPECT_GE(p50, 500.0);
  EXPECT_LE(p50, 500.0 * 1.25);
  EXPECT_GE(p99, 990.0);
  EXPECT_LE(p99, 1000.0);  // clamped to the max seen
  for (uint32_t b = 1; b < LatencyHistogram::kBuckets; ++b) {
    EXPECT_GT(LatencyHistogram::bucket_upper(b), LatencyHistogram::bucket_upper(b - 1));
  }
  for (uint64_t v : {0ull, 3ull, 4ull, 9ull, 10ull, 1234567ull}) {
    EXPECT_LE(v, LatencyHistogram::bucket_upper(LatencyHistogram::bucket_of(v)));
  }
}

}  // namespace
}  // namespace texstream::server
