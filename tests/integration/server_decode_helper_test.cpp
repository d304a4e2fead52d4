// DecodeHelperPool against real texstream-decode processes: mips decoded out of process equal OpenImageIO's
// own read; a helper that crashes or hangs fails that one decode with an error naming the file and is
// replaced on the next decode; texstream-server itself does not link OpenImageIO.
#include <sys/stat.h>
#include <unistd.h>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "../support/patience.hpp"
#include "texstream/common/texel_format.hpp"
#include "texstream/server/decode/decode_helper_pool.hpp"
#include "texstream/server/storage/posix_storage.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;

namespace texstream::server {
namespace {

const fs::path kHelper = fs::path(TEXSTREAM_BIN_DIR) / "texstream-decode";

class DecodeHelperTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("texstream-decode-test-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    tx_ = dir_ / "0.tx";
    OIIO::ImageSpec spec(64, 32, 3, OIIO::TypeDesc::UINT8);
    OIIO::ImageBuf src(spec);
    for (int y = 0; y < 32; ++y) {
      for (int x = 0; x < 64; ++x) {
        float px[3] = {float(x) / 64.0f, float(y) / 32.0f, float((x * 7 + y * 3) % 16) / 15.0f};
        src.setpixel(x, y, px, 3);
      }
    }
    OIIO::ImageSpec config;
    config.tile_width = 16;
    config.tile_height = 16;
    ASSERT_TRUE(OIIO::ImageBufAlgo::make_texture(OIIO::ImageBufAlgo::MakeTxTexture, src, tx_.string(), config))
        << OIIO::geterror();
  }
  void TearDown() override { fs::remove_all(dir_); }

  // A shell script standing in for the helper.
  fs::path script(const std::string& name, const std::string& body) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << "#!/bin/sh\n" << body << "\n";
    ::chmod(p.c_str(), 0755);
    return p;
  }

  Status decode(DecodeHelperPool& pool, uint32_t level, std::vector<std::byte>& out, uint64_t& bytes_read) {
    Result<std::unique_ptr<StorageFile>> f = storage_.open(tx_);
    EXPECT_TRUE(f.ok());
    const Extent2D e = mip_extent(64, 32, level);
    out.assign(size_t{e.width} * e.height * 4, std::byte{0});
    bytes_read = 0;
    return pool.decode(**f, tx_, level, e, out, bytes_read);
  }

  fs::path dir_;
  fs::path tx_;
  PosixStorage storage_;
};

TEST_F(DecodeHelperTest, EveryMipEqualsOpenImageIOsOwnReadAndOneHelperServesThemAll) {
  DecodeHelperPool pool(kHelper);
  auto in = OIIO::ImageInput::open(tx_.string());
  ASSERT_TRUE(in);
  for (uint32_t level = 0; level < 7; ++level) {
    ASSERT_TRUE(in->seek_subimage(0, static_cast<int>(level)));
    const Extent2D e = mip_extent(64, 32, level);
    std::vector<uint8_t> ref(size_t{e.width} * e.height * 3);
    ASSERT_TRUE(in->read_image(0, static_cast<int>(level), 0, 3, OIIO::TypeDesc::UINT8, ref.data()));
    std::vector<std::byte> out;
    uint64_t bytes_read = 0;
    const Status s = decode(pool, level, out, bytes_read);
    ASSERT_TRUE(s.ok()) << s.error().message;
    EXPECT_GT(bytes_read, 0u);
    for (size_t i = 0; i < size_t{e.width} * e.height; ++i) {
      for (int k = 0; k < 3; ++k) ASSERT_EQ(std::to_integer<uint8_t>(out[i * 4 + k]), ref[i * 3 + k]) << level;
      ASSERT_EQ(std::to_integer<uint8_t>(out[i * 4 + 3]), 255);
    }
  }
  EXPECT_EQ(pool.helpers_started(), 1u);
  // A file error is the file's: the helper stays and serves the next decode.
  std::vector<std::byte> out;
  uint64_t bytes_read = 0;
  Result<std::unique_ptr<StorageFile>> f = storage_.open(tx_);
  ASSERT_TRUE(f.ok());
  std::vector<std::byte> big(128 * 128 * 4);
  const Status wrong = pool.decode(**f, tx_, 0, Extent2D{128, 128}, big, bytes_read);
  ASSERT_FALSE(wrong.ok());
  EXPECT_EQ(wrong.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(wrong.error().message.find(tx_.string()), std::string::npos) << wrong.error().message;
  EXPECT_TRUE(decode(pool, 1, out, bytes_read).ok());
  EXPECT_EQ(pool.helpers_started(), 1u);
}

TEST_F(DecodeHelperTest, ACrashIsAnErrorNamingTheFileAndTheNextDecodeStartsAFreshHelper) {
  // Crashes the first time it is started, behaves like the real helper after that.
  const fs::path mark = dir_ / "crashed-once";
  const fs::path fake = script("crash-once.sh", "if [ ! -e '" + mark.string() + "' ]; then : > '" + mark.string() +
                                                    "'; kill -SEGV $$; fi\nexec '" + kHelper.string() + "' \"$@\"");
  DecodeHelperPool pool(fake);
  std::vector<std::byte> out;
  uint64_t bytes_read = 0;
  const Status crashed = decode(pool, 0, out, bytes_read);
  ASSERT_FALSE(crashed.ok());
  EXPECT_EQ(crashed.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(crashed.error().message.find(tx_.string()), std::string::npos) << crashed.error().message;
  EXPECT_NE(crashed.error().message.find("signal 11"), std::string::npos) << crashed.error().message;
  const Status again = decode(pool, 0, out, bytes_read);
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_EQ(pool.helpers_started(), 2u);
}

TEST_F(DecodeHelperTest, AHungHelperTimesOutAndIsKilled) {
  DecodeHelperPool pool(script("hang.sh", "exec sleep 30"), 300ms);
  std::vector<std::byte> out;
  uint64_t bytes_read = 0;
  const auto t0 = std::chrono::steady_clock::now();
  const Status hung = decode(pool, 0, out, bytes_read);
  const auto waited = std::chrono::steady_clock::now() - t0;
  ASSERT_FALSE(hung.ok());
  EXPECT_EQ(hung.error().code, ErrorCode::kTimeout);
  EXPECT_NE(hung.error().message.find(tx_.string()), std::string::npos) << hung.error().message;
  // The 300 ms timeout, then the kill: not the helper's 30 s sleep.
  EXPECT_LT(waited, 300ms + test::promptly(500ms));
}

TEST_F(DecodeHelperTest, AMissingHelperIsAnIoErrorNotACrash) {
  DecodeHelperPool pool(dir_ / "no-such-helper");
  std::vector<std::byte> out;
  uint64_t bytes_read = 0;
  const Status s = decode(pool, 0, out, bytes_read);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, ErrorCode::kIo);
  EXPECT_NE(s.error().message.find(tx_.string()), std::string::npos) << s.error().message;
}

TEST(DecodeHelperLinkTest, TexstreamServerDoesNotLinkOpenImageIO) {
  const std::string cmd = "ldd '" + (fs::path(TEXSTREAM_BIN_DIR) / "texstream-server").string() + "'";
  FILE* p = ::popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string out;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof(buf), p)) > 0) out.append(buf, n);
  ASSERT_EQ(::pclose(p), 0) << out;
  EXPECT_NE(out.find("libc.so"), std::string::npos) << out;
  EXPECT_EQ(out.find("OpenImageIO"), std::string::npos) << out;
}

}  // namespace
}  // namespace texstream::server
