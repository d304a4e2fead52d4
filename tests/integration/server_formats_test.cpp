// Texture files other than the generator's DDS, served by a Server in this process over a real segment:
// tiled mipmapped TIFF (.tx) and OpenEXR (.exr) made by OpenImageIO's make_texture (what `maketx` runs),
// a DX10 BC1 DDS (served raw, never decoded), a BGRA DDS (decoded to RGBA8), and error completions for
// missing, corrupt, truncated and mismatched files in every format.
#include <unistd.h>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <thread>
#include <tuple>
#include <vector>

#include "../support/patience.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/checksum.hpp"
#include "texstream/protocol/doorbell.hpp"
#include "texstream/protocol/liveness.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/server/dispatch/server.hpp"
#include "texstream/server/load/texture_file_index.hpp"
#include "texstream/server/storage/posix_storage.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;

namespace texstream::server {
namespace {

enum Tex : uint32_t {
  kTiff = 0,          // 64x32 RGB uint8 .tx (maketx)
  kExr = 1,           // 32x32 RGBA half .exr (maketx)
  kDx10Bc1 = 2,       // 16x16 BC1 DDS with the DX10 header, 5 mips
  kBgraDds = 3,       // 8x8 BGRA8 DDS, 4 mips: decoded to RGBA8
  kTiffMismatch = 4,  // table 128x128, file 64x32
  kTiffTruncated = 5,
  kExrTruncated = 6,
  kMissing = 7,        // no file at all
  kBc1FromTiff = 8,    // table says bc1, file is .tx: the server never encodes BC1
  kGarbageTif = 9,     // random bytes named .tif
  kDdsTruncated = 10,  // DX10 BC1 cut inside mip 0
  kGreyTiff = 11,      // 16x16 one-channel .tif (maketx)
  kScanlineCut = 12,   // 64x64 RGB scanline (untiled, uncompressed) .tif cut in half: OIIO 2.4 reads "ok"
  kCount = 13,
};

float srgb_encode(float l) {
  l = std::clamp(l, 0.0f, 1.0f);
  return l <= 0.0031308f ? 12.92f * l : 1.055f * std::pow(l, 1.0f / 2.4f) - 0.055f;
}

void write_file(const fs::path& p, const std::vector<std::byte>& bytes) {
  fs::create_directories(p.parent_path());
  std::ofstream f(p, std::ios::binary);
  f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

std::vector<std::byte> read_file(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::vector<char> c((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  std::vector<std::byte> out(c.size());
  std::memcpy(out.data(), c.data(), c.size());
  return out;
}

// An image with a gradient and per-channel variation, written as a mipmapped tiled texture.
void make_tx(const fs::path& out, int w, int h, int channels, OIIO::TypeDesc type) {
  OIIO::ImageSpec spec(w, h, channels, type);
  OIIO::ImageBuf src(spec);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      float px[4] = {float(x) / float(w), float(y) / float(h), float((x * 7 + y * 3) % 16) / 15.0f, 0.75f};
      src.setpixel(x, y, px, channels);
    }
  }
  OIIO::ImageSpec config;
  config.tile_width = 16;
  config.tile_height = 16;
  config.attribute("maketx:filtername", "box");
  fs::create_directories(out.parent_path());
  ASSERT_TRUE(OIIO::ImageBufAlgo::make_texture(OIIO::ImageBufAlgo::MakeTxTexture, src, out.string(), config))
      << OIIO::geterror();
}

// DDS with the DX10 extension and BC1 blocks (DXGI 71), as texconv writes it.
std::vector<std::byte> dx10_bc1(uint32_t w, uint32_t h, uint32_t mips) {
  uint32_t words[37] = {};
  words[0] = 0x20534444u;
  words[1] = 124;
  words[2] = 0x1 | 0x2 | 0x4 | 0x1000 | 0x20000 | 0x80000;
  words[3] = h;
  words[4] = w;
  words[7] = mips;
  words[19] = 32;
  words[20] = 0x4;
  words[21] = 0x30315844u;  // "DX10"
  words[27] = 0x1000 | 0x400000 | 0x8;
  words[32] = 71;  // DXGI_FORMAT_BC1_UNORM
  words[33] = 3;   // TEXTURE2D
  words[35] = 1;
  std::vector<std::byte> out(148);
  std::memcpy(out.data(), words, 148);
  const uint64_t data = mip_chain_offset(TexelFormat::kBc1, w, h, mips);
  for (uint64_t i = 0; i < data; ++i) out.push_back(static_cast<std::byte>((i * 29 + 3) & 0xff));
  return out;
}

// Uncompressed DDS with B,G,R,A byte order (masks), which we cannot hand over raw.
std::vector<std::byte> bgra_dds(uint32_t w, uint32_t h, uint32_t mips) {
  uint32_t words[32] = {};
  words[0] = 0x20534444u;
  words[1] = 124;
  words[2] = 0x1 | 0x2 | 0x4 | 0x8 | 0x1000 | 0x20000;
  words[3] = h;
  words[4] = w;
  words[5] = w * 4;
  words[7] = mips;
  words[19] = 32;
  words[20] = 0x40 | 0x1;  // RGB | ALPHAPIXELS
  words[22] = 32;
  words[23] = 0x00ff0000u;  // R
  words[24] = 0x0000ff00u;  // G
  words[25] = 0x000000ffu;  // B
  words[26] = 0xff000000u;  // A
  words[27] = 0x1000 | 0x400000 | 0x8;
  std::vector<std::byte> out(128);
  std::memcpy(out.data(), words, 128);
  for (uint32_t m = 0; m < mips; ++m) {
    const Extent2D e = mip_extent(w, h, m);
    for (uint32_t i = 0; i < e.width * e.height; ++i) {
      // Texel i of mip m has R = i, G = m * 40, B = 200, A = 100 + i; stored B, G, R, A.
      out.push_back(std::byte{200});
      out.push_back(static_cast<std::byte>(m * 40));
      out.push_back(static_cast<std::byte>(i & 0xff));
      out.push_back(static_cast<std::byte>((100 + i) & 0xff));
    }
  }
  return out;
}

class ServerFormatsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    name_ = "texstream-srvfmt-" + std::to_string(getpid());
    dir_ = fs::temp_directory_path() / name_;
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    const auto rgba = uint32_t(TexelFormat::kRgba8), bc1 = uint32_t(TexelFormat::kBc1);
    table_ = {
        {64, 32, full_mip_count(64, 32), rgba},
        {32, 32, full_mip_count(32, 32), rgba},
        {16, 16, 5, bc1},
        {8, 8, 4, rgba},
        {128, 128, full_mip_count(128, 128), rgba},
        {64, 32, full_mip_count(64, 32), rgba},
        {32, 32, full_mip_count(32, 32), rgba},
        {8, 8, 4, rgba},
        {64, 32, full_mip_count(64, 32), bc1},
        {16, 16, 5, rgba},
        {16, 16, 5, bc1},
        {16, 16, 5, rgba},
        {64, 64, full_mip_count(64, 64), rgba},
    };
    ASSERT_EQ(table_.size(), size_t{kCount});
    ASSERT_TRUE(scene::write_texture_table(dir_, table_).ok());
    const auto path = [&](uint32_t t, TextureFileKind k) { return texture_file_path(dir_, TextureId(t), k); };
    make_tx(path(kTiff, TextureFileKind::kTx), 64, 32, 3, OIIO::TypeDesc::UINT8);
    make_tx(path(kExr, TextureFileKind::kExr), 32, 32, 4, OIIO::TypeDesc::HALF);
    write_file(path(kDx10Bc1, TextureFileKind::kDds), dx10_bc1(16, 16, 5));
    write_file(path(kBgraDds, TextureFileKind::kDds), bgra_dds(8, 8, 4));
    fs::copy_file(path(kTiff, TextureFileKind::kTx), path(kTiffMismatch, TextureFileKind::kTx));
    for (auto [t, kind] : {std::pair{kTiffTruncated, TextureFileKind::kTx}, {kExrTruncated, TextureFileKind::kExr}}) {
      const uint32_t src_t = kind == TextureFileKind::kTx ? kTiff : kExr;
      std::vector<std::byte> bytes = read_file(path(src_t, kind));
      bytes.resize(bytes.size() * 2 / 3);
      write_file(path(t, kind), bytes);
    }
    fs::copy_file(path(kTiff, TextureFileKind::kTx), path(kBc1FromTiff, TextureFileKind::kTx));
    std::vector<std::byte> garbage(5000);
    for (size_t i = 0; i < garbage.size(); ++i) garbage[i] = static_cast<std::byte>((i * 7919) >> 3);
    write_file(path(kGarbageTif, TextureFileKind::kTif), garbage);
    std::vector<std::byte> cut = dx10_bc1(16, 16, 5);
    cut.resize(148 + 64);
    write_file(path(kDdsTruncated, TextureFileKind::kDds), cut);
    make_tx(path(kGreyTiff, TextureFileKind::kTif), 16, 16, 1, OIIO::TypeDesc::UINT8);
    {
      const fs::path p = path(kScanlineCut, TextureFileKind::kTif);
      auto out = OIIO::ImageOutput::create(p.string());
      ASSERT_TRUE(out);
      OIIO::ImageSpec spec(64, 64, 3, OIIO::TypeDesc::UINT8);
      spec.attribute("compression", "none");
      ASSERT_TRUE(out->open(p.string(), spec));
      std::vector<uint8_t> px(64 * 64 * 3);
      for (size_t i = 0; i < px.size(); ++i) px[i] = static_cast<uint8_t>(i * 5);
      ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px.data()));
      out->close();
      std::vector<std::byte> bytes = read_file(p);
      bytes.resize(bytes.size() / 2);
      write_file(p, bytes);
    }

    SegmentParams params;
    params.slot_count = 8;
    params.slot_bytes = 64 * 1024;
    auto seg = Segment::create(name_, params);
    ASSERT_TRUE(seg.ok()) << seg.error().message;
    segment_ = std::move(seg).value();
    requests_ = segment_->request_producer();
    completions_ = segment_->completion_consumer();
    ServerConfig config;
    config.idle_wait_ms = 5;
    auto server = Server::create(*segment_, dir_, config, storage_);
    ASSERT_TRUE(server.ok()) << server.error().message;
    server_ = std::move(server).value();
    thread_ = std::thread([this] { server_->run(stop_); });
  }

  void TearDown() override {
    if (thread_.joinable()) {
      stop_ = true;
      Doorbell(*segment_).wake_all();
      thread_.join();
    }
    server_.reset();
    segment_.reset();
    fs::remove_all(dir_);
  }

  // Loads one mip and waits for its completion; the slot is released after `check` ran.
  template <class Check>
  void load(uint32_t texture, uint32_t mip, Check check) {
    RequestRecord r{};
    r.kind = static_cast<uint32_t>(RequestKind::kLoad);
    r.texture_id = texture;
    r.mip_level = mip;
    r.generation = ++generation_;
    r.priority = 1;
    ASSERT_TRUE(requests_.try_push(r));
    ring();
    std::optional<CompletionRecord> c;
    const auto deadline = std::chrono::steady_clock::now() + test::kHangAfter;
    while (!(c = completions_.try_pop())) {
      ASSERT_LT(std::chrono::steady_clock::now(), deadline) << "no completion for texture " << texture;
      std::this_thread::sleep_for(200us);
    }
    ASSERT_EQ(c->texture_id, texture);
    ASSERT_EQ(c->mip_level, mip);
    check(*c);
    if (c->status == uint32_t(CompletionStatus::kOk)) {
      RequestRecord rel{};
      rel.kind = static_cast<uint32_t>(RequestKind::kReleaseSlot);
      rel.slot = c->slot;
      ASSERT_TRUE(requests_.try_push(rel));
      ring();
    }
  }
  void ring() { Doorbell(*segment_).ring(); }
  CompletionStatus status_of(uint32_t texture, uint32_t mip) {
    CompletionStatus s{};
    load(texture, mip, [&](const CompletionRecord& c) { s = CompletionStatus(c.status); });
    return s;
  }
  std::span<const std::byte> payload(const CompletionRecord& c) {
    EXPECT_EQ(c.status, uint32_t(CompletionStatus::kOk)) << to_string(CompletionStatus(c.status));
    const std::span<std::byte> slot = segment_->slot(c.slot);
    EXPECT_EQ(c.checksum, payload_checksum(slot.data(), c.byte_size));
    return slot.first(c.byte_size);
  }
  // What OpenImageIO itself reads for that level (the reference), as float.
  std::vector<float> reference(uint32_t texture, TextureFileKind kind, uint32_t mip, int* channels) {
    auto in = OIIO::ImageInput::open(texture_file_path(dir_, TextureId(texture), kind).string());
    EXPECT_TRUE(in);
    EXPECT_TRUE(in->seek_subimage(0, static_cast<int>(mip)));
    *channels = in->spec().nchannels;
    std::vector<float> px(size_t(in->spec().width) * in->spec().height * *channels);
    EXPECT_TRUE(in->read_image(0, static_cast<int>(mip), 0, *channels, OIIO::TypeDesc::FLOAT, px.data()));
    return px;
  }

  std::string name_;
  fs::path dir_;
  std::vector<scene::TextureRecord> table_;
  std::unique_ptr<Segment> segment_;
  SpscRingProducer<RequestRecord> requests_;
  SpscRingConsumer<CompletionRecord> completions_;
  PosixStorage storage_;
  std::unique_ptr<Server> server_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  uint64_t generation_ = 0;
};

TEST_F(ServerFormatsTest, TiledTiffServesEachMipAsRgba8) {
  for (uint32_t mip = 0; mip < table_[kTiff].mip_count; ++mip) {
    int ch = 0;
    const std::vector<float> ref = reference(kTiff, TextureFileKind::kTx, mip, &ch);
    ASSERT_EQ(ch, 3);
    load(kTiff, mip, [&](const CompletionRecord& c) {
      const Extent2D e = mip_extent(64, 32, mip);
      EXPECT_EQ(c.format, uint32_t(TexelFormat::kRgba8));
      EXPECT_EQ(c.width, e.width);
      EXPECT_EQ(c.height, e.height);
      ASSERT_EQ(c.byte_size, uint64_t{e.width} * e.height * 4);
      const auto p = payload(c);
      for (size_t i = 0; i < size_t{e.width} * e.height; ++i) {
        for (int k = 0; k < 3; ++k) {
          ASSERT_EQ(std::to_integer<int>(p[i * 4 + k]), int(std::lround(ref[i * 3 + k] * 255.0f)))
              << "mip " << mip << " texel " << i;
        }
        ASSERT_EQ(std::to_integer<int>(p[i * 4 + 3]), 255);
      }
    });
  }
  // Exact reads: only the tiles of the asked levels (and headers), not the whole file each time.
  const double amp = read_amplification(server_->stats());
  EXPECT_GT(amp, 0.0);
}

TEST_F(ServerFormatsTest, OpenExrHalfIsSrgbEncodedRgba8) {
  for (uint32_t mip : {0u, 2u, 5u}) {
    int ch = 0;
    const std::vector<float> ref = reference(kExr, TextureFileKind::kExr, mip, &ch);
    ASSERT_EQ(ch, 4);
    load(kExr, mip, [&](const CompletionRecord& c) {
      const auto p = payload(c);
      const Extent2D e = mip_extent(32, 32, mip);
      ASSERT_EQ(p.size(), size_t{e.width} * e.height * 4);
      for (size_t i = 0; i < size_t{e.width} * e.height; ++i) {
        for (int k = 0; k < 3; ++k) {
          ASSERT_NEAR(std::to_integer<int>(p[i * 4 + k]), srgb_encode(ref[i * 4 + k]) * 255.0f, 1.0);
        }
        ASSERT_NEAR(std::to_integer<int>(p[i * 4 + 3]), ref[i * 4 + 3] * 255.0f, 1.0);  // alpha stays linear
      }
    });
  }
}

TEST_F(ServerFormatsTest, OneChannelTiffBecomesGreyOpaqueRgba8) {
  int ch = 0;
  const std::vector<float> ref = reference(kGreyTiff, TextureFileKind::kTif, 1, &ch);
  ASSERT_EQ(ch, 1);
  load(kGreyTiff, 1, [&](const CompletionRecord& c) {
    const auto p = payload(c);
    ASSERT_EQ(p.size(), 8u * 8u * 4u);
    for (size_t i = 0; i < 64; ++i) {
      const int g = int(std::lround(ref[i] * 255.0f));
      ASSERT_EQ(std::to_integer<int>(p[i * 4 + 0]), g);
      ASSERT_EQ(std::to_integer<int>(p[i * 4 + 2]), g);
      ASSERT_EQ(std::to_integer<int>(p[i * 4 + 3]), 255);
    }
  });
}

TEST_F(ServerFormatsTest, Dx10Bc1DdsIsServedAsRawBlocks) {
  const std::vector<std::byte> file = dx10_bc1(16, 16, 5);
  for (uint32_t mip = 0; mip < 5; ++mip) {
    load(kDx10Bc1, mip, [&](const CompletionRecord& c) {
      EXPECT_EQ(c.format, uint32_t(TexelFormat::kBc1));
      const auto p = payload(c);
      const uint64_t offset = 148 + mip_chain_offset(TexelFormat::kBc1, 16, 16, mip);
      ASSERT_EQ(p.size(), mip_bytes(TexelFormat::kBc1, 16, 16, mip));
      EXPECT_EQ(std::memcmp(p.data(), file.data() + offset, p.size()), 0) << "mip " << mip;
    });
  }
}

TEST_F(ServerFormatsTest, BgraDdsIsDecodedToRgba8) {
  for (uint32_t mip = 0; mip < 4; ++mip) {
    load(kBgraDds, mip, [&](const CompletionRecord& c) {
      const auto p = payload(c);
      const Extent2D e = mip_extent(8, 8, mip);
      ASSERT_EQ(p.size(), size_t{e.width} * e.height * 4);
      for (uint32_t i = 0; i < e.width * e.height; ++i) {
        ASSERT_EQ(std::to_integer<uint32_t>(p[i * 4 + 0]), i & 0xff) << "mip " << mip << " texel " << i;
        ASSERT_EQ(std::to_integer<uint32_t>(p[i * 4 + 1]), mip * 40);
        ASSERT_EQ(std::to_integer<uint32_t>(p[i * 4 + 2]), 200u);
        ASSERT_EQ(std::to_integer<uint32_t>(p[i * 4 + 3]), (100 + i) & 0xff);
      }
    });
  }
}

// A file cut at 2/3: the levels whose tiles survive may be served, but only with exactly the pixels of the
// intact file; the others must be kCorrupt — never "ok" with wrong pixels (OIIO 2.4 returns true from
// truncated TIFF reads; has_error() tells).
TEST_F(ServerFormatsTest, TruncatedTiffAndExrGiveCorruptOrExactPixelsNeverWrongOnes) {
  for (auto [t, intact, kind] : {std::tuple{kTiffTruncated, kTiff, TextureFileKind::kTx},
                                 std::tuple{kExrTruncated, kExr, TextureFileKind::kExr}}) {
    uint32_t corrupt = 0;
    for (uint32_t mip = 0; mip < table_[t].mip_count; ++mip) {
      int ch = 0;
      const std::vector<float> ref = reference(intact, kind, mip, &ch);
      load(t, mip, [&](const CompletionRecord& c) {
        if (c.status == uint32_t(CompletionStatus::kCorrupt)) {
          ++corrupt;
          return;
        }
        const auto p = payload(c);
        const Extent2D e = mip_extent(table_[t].width, table_[t].height, mip);
        ASSERT_EQ(p.size(), size_t{e.width} * e.height * 4);
        for (size_t i = 0; i < size_t{e.width} * e.height; ++i) {
          const float v = kind == TextureFileKind::kExr ? srgb_encode(ref[i * ch]) : ref[i * ch];
          ASSERT_NEAR(std::to_integer<int>(p[i * 4]), v * 255.0f, 1.0) << "texture " << t << " mip " << mip;
        }
      });
    }
    EXPECT_GT(corrupt, 0u) << "texture " << t << ": a file cut at 2/3 must fail somewhere";
  }
}

TEST_F(ServerFormatsTest, ErrorsInEveryFormatAreCompletionsAndServingGoesOn) {
  EXPECT_EQ(status_of(kTiffMismatch, 0), CompletionStatus::kCorrupt);  // 64x32 in the file, 128x128 in the table
  EXPECT_EQ(status_of(kMissing, 0), CompletionStatus::kNotFound);
  EXPECT_EQ(status_of(kBc1FromTiff, 0), CompletionStatus::kCorrupt);
  EXPECT_EQ(status_of(kGarbageTif, 0), CompletionStatus::kCorrupt);
  EXPECT_EQ(status_of(kDdsTruncated, 0), CompletionStatus::kCorrupt);  // 128 bytes of mip 0, 64 in the file
  EXPECT_EQ(status_of(kScanlineCut, 0), CompletionStatus::kCorrupt);   // read_image says true; has_error() not
  EXPECT_EQ(status_of(kScanlineCut, 1), CompletionStatus::kCorrupt);   // a plain TIFF has no mip 1
  EXPECT_EQ(status_of(kDx10Bc1, 0), CompletionStatus::kOk);            // the others are still served
  EXPECT_EQ(server_->stats().corrupt.load(), 6u);
  EXPECT_EQ(server_->stats().not_found.load(), 1u);
}

}  // namespace
}  // namespace texstream::server
