// PosixStorage::open_lazy and UringReader (issue 29): a file opened by its first read gives the bytes a
// pread gives, in one kernel crossing per read with io_uring; a missing file is kNotFound from the read; a
// FIFO in a file's place is refused as not a file without blocking; a read past the end returns what is
// there; and with io_uring switched off every one of these reads the same through the ordinary path.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "texstream/common/syscall_count.hpp"
#include "texstream/server/storage/posix_storage.hpp"
#include "texstream/server/storage/uring_reader.hpp"

namespace texstream::server {
namespace {

namespace fs = std::filesystem;

class UringRead : public ::testing::TestWithParam<bool> {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("texstream-uring-" + std::to_string(getpid()));
    fs::create_directories(dir_);
    bytes_.resize(100'000);
    for (size_t i = 0; i < bytes_.size(); ++i) bytes_[i] = static_cast<std::byte>((i * 131) ^ (i >> 7));
    std::ofstream(dir_ / "a.dds", std::ios::binary).write(reinterpret_cast<const char*>(bytes_.data()), bytes_.size());
    UringReader::set_enabled(GetParam());
  }
  void TearDown() override {
    UringReader::set_enabled(true);
    fs::remove_all(dir_);
  }
  // Runs `f` on a fresh thread: a thread decides once whether it has a reader (set_enabled before it asks).
  template <class F>
  void on_new_thread(F&& f) {
    std::thread t(std::forward<F>(f));
    t.join();
  }

  std::unique_ptr<StorageFile> open_a(PosixStorage& storage) {
    auto f = storage.open_lazy((dir_ / "a.dds").string());
    EXPECT_TRUE(f.ok());
    return f.ok() ? std::move(f).value() : nullptr;
  }

  fs::path dir_;
  std::vector<std::byte> bytes_;
};

TEST_P(UringRead, ScatterReadEqualsTheFileInOneCrossingWithIoUring) {
  on_new_thread([&] {
    // Where the kernel refuses io_uring the lazy file must read the ordinary way, with the same bytes.
    const bool uring = GetParam() && UringReader::available();
    PosixStorage storage;
    const std::unique_ptr<StorageFile> f = open_a(storage);
    ASSERT_NE(f, nullptr);
    std::vector<std::byte> a(1000), b(30'000), c(5);
    const std::array<std::span<std::byte>, 3> parts{a, b, c};
    SyscallCounter counted;
    {
      const SyscallAccount account(counted);
      Result<uint64_t> got = f->read_scatter_at(parts, 777);
      ASSERT_TRUE(got.ok()) << got.error().message;
      EXPECT_EQ(*got, a.size() + b.size() + c.size());
    }
    EXPECT_EQ(std::memcmp(a.data(), bytes_.data() + 777, a.size()), 0);
    EXPECT_EQ(std::memcmp(b.data(), bytes_.data() + 777 + a.size(), b.size()), 0);
    EXPECT_EQ(std::memcmp(c.data(), bytes_.data() + 777 + a.size() + b.size(), c.size()), 0);
    if (uring) {
      EXPECT_EQ(counted.total(), 1u) << counted.describe();  // open + read + close: one io_uring_enter
      EXPECT_EQ(counted.of(Syscall::kIoUring), 1u);
    } else {
      EXPECT_EQ(counted.of(Syscall::kIoUring), 0u);
      EXPECT_EQ(counted.of(Syscall::kRead), 1u);  // opened by open_lazy already (the ordinary way)
    }
  });
}

TEST_P(UringRead, AReadPastTheEndReturnsWhatIsThere) {
  on_new_thread([&] {
    PosixStorage storage;
    const std::unique_ptr<StorageFile> f = open_a(storage);
    ASSERT_NE(f, nullptr);
    std::vector<std::byte> out(5000);
    Result<uint64_t> got = f->read_at(out, bytes_.size() - 1234);
    ASSERT_TRUE(got.ok());
    EXPECT_EQ(*got, 1234u);
    EXPECT_EQ(std::memcmp(out.data(), bytes_.data() + bytes_.size() - 1234, 1234), 0);
    got = f->read_at(out, bytes_.size() + 10);
    ASSERT_TRUE(got.ok());
    EXPECT_EQ(*got, 0u);
  });
}

TEST_P(UringRead, AMissingFileIsNotFoundFromTheReadNamingIt) {
  on_new_thread([&] {
    PosixStorage storage;
    const std::string path = (dir_ / "missing.dds").string();
    auto f = storage.open_lazy(path);
    if (!f.ok()) {  // without io_uring the open itself says it
      EXPECT_EQ(f.error().code, ErrorCode::kNotFound);
      return;
    }
    std::vector<std::byte> out(64);
    Result<uint64_t> got = f.value()->read_at(out, 0);
    ASSERT_FALSE(got.ok());
    EXPECT_EQ(got.error().code, ErrorCode::kNotFound);
    EXPECT_NE(got.error().message.find(path), std::string::npos) << got.error().message;
  });
}

TEST_P(UringRead, AFifoInAFilesPlaceIsRefusedWithoutBlocking) {
  const fs::path fifo = dir_ / "fifo.dds";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  on_new_thread([&] {
    PosixStorage storage;
    auto f = storage.open_lazy(fifo.string());
    ASSERT_TRUE(f.ok());
    std::vector<std::byte> out(64);
    Result<uint64_t> got = f.value()->read_at(out, 0);  // a read that blocked would hang here (ctest times out)
    ASSERT_FALSE(got.ok());
    EXPECT_EQ(got.error().code, ErrorCode::kNotAFile) << got.error().message;
  });
}

TEST_P(UringRead, AFileReplacedBetweenReadsIsReadAsItIsNow) {
  on_new_thread([&] {
    PosixStorage storage;
    const std::unique_ptr<StorageFile> f = open_a(storage);
    ASSERT_NE(f, nullptr);
    std::vector<std::byte> out(16);
    ASSERT_TRUE(f->read_at(out, 0).ok());
    if (!GetParam()) return;  // an open descriptor reads the file it opened: that is the ordinary way's contract
    // Each io_uring read opens the path again: a file swapped in place is read as it is now.
    std::ofstream(dir_ / "b.tmp", std::ios::binary).write("0123456789abcdef", 16);
    fs::rename(dir_ / "b.tmp", dir_ / "a.dds");
    ASSERT_TRUE(f->read_at(out, 0).ok());
    EXPECT_EQ(std::memcmp(out.data(), "0123456789abcdef", 16), 0);
  });
}

INSTANTIATE_TEST_SUITE_P(IoUringOnAndOff, UringRead, ::testing::Values(true, false),
                         [](const auto& p) { return p.param ? "io_uring" : "pread"; });

}  // namespace
}  // namespace texstream::server
