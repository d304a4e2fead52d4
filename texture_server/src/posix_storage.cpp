#include "texstream/server/posix_storage.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>

namespace texstream::server {

namespace {

class PosixFile final : public StorageFile {
 public:
  PosixFile(int fd, std::filesystem::path path) : fd_(fd), path_(std::move(path)) {}
  ~PosixFile() override { ::close(fd_); }
  PosixFile(const PosixFile&) = delete;
  PosixFile& operator=(const PosixFile&) = delete;

  Result<uint64_t> read_at(std::span<std::byte> out, uint64_t offset) override {
    uint64_t done = 0;
    // pread may return fewer bytes than asked (signals, some file systems): loop until all, EOF or error.
    while (done < out.size()) {
      const ssize_t n = ::pread(fd_, out.data() + done, out.size() - done, static_cast<off_t>(offset + done));
      if (n < 0) {
        if (errno == EINTR) continue;
        return make_error(ErrorCode::kIo, "cannot read " + std::to_string(out.size()) + " bytes at offset " +
                                              std::to_string(offset) + " of '" + path_.string() +
                                              "': " + std::strerror(errno));
      }
      if (n == 0) break;  // end of file
      done += static_cast<uint64_t>(n);
    }
    return done;
  }

  Result<uint64_t> size() override {
    struct stat st {};
    if (::fstat(fd_, &st) != 0) {
      return make_error(ErrorCode::kIo, "cannot stat '" + path_.string() + "': " + std::strerror(errno));
    }
    return static_cast<uint64_t>(st.st_size);
  }

 private:
  int fd_;
  std::filesystem::path path_;
};

}  // namespace

Result<std::unique_ptr<StorageFile>> PosixStorage::open(const std::filesystem::path& path) {
  int fd;
  do {
    fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  } while (fd < 0 && errno == EINTR);
  if (fd < 0) {
    const int err = errno;
    const ErrorCode code = (err == ENOENT || err == ENOTDIR) ? ErrorCode::kNotFound : ErrorCode::kIo;
    return make_error(code, "cannot open '" + path.string() + "': " + std::strerror(err));
  }
  return std::unique_ptr<StorageFile>(new PosixFile(fd, path));
}

}  // namespace texstream::server
