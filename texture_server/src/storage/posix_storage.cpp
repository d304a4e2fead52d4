#include "texstream/server/storage/posix_storage.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <string>

#include "texstream/common/syscall_count.hpp"
#include "texstream/server/storage/uring_reader.hpp"

namespace texstream::server {

namespace {

class PosixFile final : public StorageFile {
 public:
  static constexpr size_t kMaxScatterParts = 32;  // a mip chain of up to 2^31 x 2^31 texels

  // The path as text, for error messages only: a std::filesystem::path copy also copies its list of
  // components (an allocation per component), once per file opened.
  PosixFile(int fd, std::string path) : fd_(fd), path_(std::move(path)) {}
  ~PosixFile() override {
    count_syscall(Syscall::kClose);
    ::close(fd_);
  }
  PosixFile(const PosixFile&) = delete;
  PosixFile& operator=(const PosixFile&) = delete;

  Result<uint64_t> read_at(std::span<std::byte> out, uint64_t offset) override {
    uint64_t done = 0;
    // pread may return fewer bytes than asked (signals, some file systems): loop until all, EOF or error.
    while (done < out.size()) {
      count_syscall(Syscall::kRead);
      const ssize_t n = ::pread(fd_, out.data() + done, out.size() - done, static_cast<off_t>(offset + done));
      if (n < 0) {
        if (errno == EINTR) continue;
        return read_error(errno, out.size(), offset);
      }
      if (n == 0) break;  // end of file
      done += static_cast<uint64_t>(n);
    }
    return done;
  }

  Result<uint64_t> read_scatter_at(std::span<const std::span<std::byte>> parts, uint64_t offset) override {
    // One preadv for all parts (a pread per mip was a syscall per mip of a coarse tail). More parts than
    // the fixed vector holds (a tail has at most ~16 mips) go the default way.
    std::array<iovec, kMaxScatterParts> iov{};
    if (parts.size() > iov.size()) return StorageFile::read_scatter_at(parts, offset);
    uint64_t total = 0;
    for (size_t i = 0; i < parts.size(); ++i) {
      iov[i] = iovec{parts[i].data(), parts[i].size()};
      total += parts[i].size();
    }
    uint64_t done = 0;
    size_t first = 0;  // the first part not completely read yet
    while (done < total) {
      count_syscall(Syscall::kRead);
      const ssize_t n =
          ::preadv(fd_, iov.data() + first, static_cast<int>(parts.size() - first), static_cast<off_t>(offset + done));
      if (n < 0) {
        if (errno == EINTR) continue;
        return read_error(errno, total, offset);
      }
      if (n == 0) break;  // end of file
      done += static_cast<uint64_t>(n);
      // A short read (signals, some file systems): skip the parts filled, trim the one filled partly.
      size_t left = static_cast<size_t>(n);
      while (first < parts.size() && left >= iov[first].iov_len) left -= iov[first++].iov_len;
      if (first < parts.size()) {
        iov[first].iov_base = static_cast<std::byte*>(iov[first].iov_base) + left;
        iov[first].iov_len -= left;
      }
    }
    return done;
  }

  Result<uint64_t> size() override {
    struct stat st {};
    count_syscall(Syscall::kStat);
    if (::fstat(fd_, &st) != 0) {
      return make_error(ErrorCode::kIo, "cannot stat '" + path_ + "': " + std::strerror(errno));
    }
    return static_cast<uint64_t>(st.st_size);
  }

 private:
  // A failed read. A texture path that names no regular file (a FIFO, a directory, a socket put in its
  // place: its pread fails with ESPIPE or EISDIR) is kNotAFile, answered kCorrupt, which the renderer does
  // not ask again for; it was kIo, asked 4 times per texture. Only this error path pays the fstat.
  Error read_error(int err, uint64_t bytes, uint64_t offset) const {
    struct stat st {};
    if (::fstat(fd_, &st) == 0 && !S_ISREG(st.st_mode)) {
      const char* kind = S_ISFIFO(st.st_mode)   ? "a FIFO"
                         : S_ISDIR(st.st_mode)  ? "a directory"
                         : S_ISSOCK(st.st_mode) ? "a socket"
                         : S_ISCHR(st.st_mode)  ? "a character device"
                         : S_ISBLK(st.st_mode)  ? "a block device"
                                                : "not a file";
      return Error{ErrorCode::kNotAFile,
                   "'" + path_ + "' is " + kind + ", not a regular file (" + std::strerror(err) + ")"};
    }
    return Error{ErrorCode::kIo, "cannot read " + std::to_string(bytes) + " bytes at offset " + std::to_string(offset) +
                                     " of '" + path_ + "': " + std::strerror(err)};
  }

  int fd_;
  std::string path_;
};

}  // namespace

// See PosixStorage::open_lazy. `dir` is the storage's kept descriptor of the file's directory (-1: by the
// full path); the storage outlives its files.
class LazyPosixFile final : public StorageFile {
 public:
  LazyPosixFile(PosixStorage& storage, int dir, std::string path, size_t name_at)
      : storage_(storage), dir_(dir), path_(std::move(path)), name_at_(name_at) {}

  Result<uint64_t> read_at(std::span<std::byte> out, uint64_t offset) override {
    const std::span<std::byte> parts[1] = {out};
    return read_scatter_at(parts, offset);
  }

  Result<uint64_t> read_scatter_at(std::span<const std::span<std::byte>> parts, uint64_t offset) override {
    uint64_t total = 0;
    for (const auto& p : parts) total += p.size();
    uint64_t done = 0;
    if (!file_ && parts.size() <= PosixFile::kMaxScatterParts) {
      if (UringReader* uring = UringReader::for_this_thread()) {
        std::array<iovec, PosixFile::kMaxScatterParts> iov{};
        for (size_t i = 0; i < parts.size(); ++i) iov[i] = iovec{parts[i].data(), parts[i].size()};
        const UringRead r =
            dir_ >= 0
                ? uring->open_read_close(dir_, path_.c_str() + name_at_, std::span(iov).first(parts.size()), offset)
                : uring->open_read_close(AT_FDCWD, path_.c_str(), std::span(iov).first(parts.size()), offset);
        if (r.outcome == UringRead::Outcome::kOpenFailed && dir_ < 0) return open_error(r.error);
        if (r.outcome == UringRead::Outcome::kOk) {
          if (r.bytes == total) return total;
          done = r.bytes;  // short: the end of the file, or only part was cached; the ordinary way goes on
        }
        // kOpenFailed through the kept directory, kWouldBlock, kFailed: the ordinary way says what it is.
      }
    }
    if (const Status opened = open_ordinary(); !opened.ok()) return opened.error();
    if (done == 0) return file_->read_scatter_at(parts, offset);
    // The rest of a short read: the parts from `done` on.
    std::array<std::span<std::byte>, PosixFile::kMaxScatterParts> rest{};
    size_t n = 0;
    uint64_t skip = done;
    for (const auto& p : parts) {
      if (skip >= p.size()) {
        skip -= p.size();
        continue;
      }
      rest[n++] = p.subspan(skip);
      skip = 0;
    }
    Result<uint64_t> more = file_->read_scatter_at(std::span(rest).first(n), offset + done);
    if (!more.ok()) return more.error();
    return done + *more;
  }

  bool lazy() const override { return file_ == nullptr; }

  Result<uint64_t> size() override {
    if (const Status opened = open_ordinary(); !opened.ok()) return opened.error();
    return file_->size();
  }

 private:
  // Opens file_ the ordinary way, once (open_text's errors as they are).
  Status open_ordinary() {
    if (file_) return ok_status();
    Result<std::unique_ptr<StorageFile>> f = storage_.open_text(path_);
    if (!f.ok()) return f.error();
    file_ = std::move(f).value();
    return ok_status();
  }

  Error open_error(int err) const {
    const ErrorCode code = (err == ENOENT || err == ENOTDIR) ? ErrorCode::kNotFound : ErrorCode::kIo;
    return Error{code, "cannot open '" + path_ + "': " + std::strerror(err)};
  }

  PosixStorage& storage_;
  int dir_;
  std::string path_;
  size_t name_at_;
  std::unique_ptr<StorageFile> file_;  // opened the ordinary way (no io_uring, or a read it could not do)
};

Result<std::unique_ptr<StorageFile>> PosixStorage::open_lazy(const std::string& full) {
  if (UringReader::for_this_thread() == nullptr) return open_text(full);
  const size_t slash = full.rfind('/');
  const bool has_dir = slash != std::string::npos && slash > 0 && slash + 1 < full.size();
  const int dir = has_dir ? directory_fd(std::string_view(full).substr(0, slash)) : -1;
  return std::unique_ptr<StorageFile>(new LazyPosixFile(*this, dir, full, dir >= 0 ? slash + 1 : 0));
}

PosixStorage::~PosixStorage() {
  for (const auto& [dir, fd] : dirs_) ::close(fd);
}

size_t PosixStorage::directories_kept() const {
  std::lock_guard lock(mutex_);
  return dirs_.size();
}

int PosixStorage::directory_fd(std::string_view dir) {
  std::lock_guard lock(mutex_);
  if (auto it = dirs_.find(dir); it != dirs_.end()) return it->second;
  if (dirs_.size() >= kMaxDirectories) return -1;
  const std::string name(dir);
  int fd;
  do {
    // O_PATH: only a handle for openat(), no read permission on the directory needed.
    count_syscall(Syscall::kOpen);
    fd = ::open(name.c_str(), O_PATH | O_DIRECTORY | O_CLOEXEC);
  } while (fd < 0 && errno == EINTR);
  if (fd < 0) return -1;
  dirs_.emplace(name, fd);
  return fd;
}

Result<std::unique_ptr<StorageFile>> PosixStorage::open(const std::filesystem::path& path) {
  return open_text(path.native());
}

Result<std::unique_ptr<StorageFile>> PosixStorage::open_text(const std::string& full) {
  const size_t slash = full.rfind('/');
  // "dir/name": relative to dir's kept descriptor; a bare name, a path ending in '/', or a directory that
  // cannot be kept: by the full path.
  const int dir = slash != std::string::npos && slash > 0 && slash + 1 < full.size()
                      ? directory_fd(std::string_view(full).substr(0, slash))
                      : -1;
  // O_NONBLOCK: a FIFO in place of a texture file would block open() until a writer came, and with it the
  // dispatcher (it opens local files itself): the renderer then killed the hung server and started another,
  // which hung on the same file, for ever (a preload never ended). Non-blocking, it opens at once and its
  // pread fails (ESPIPE: kNotAFile, see read_error). On regular files the flag changes nothing.
  constexpr int kFlags = O_RDONLY | O_CLOEXEC | O_NONBLOCK;
  int fd;
  do {
    count_syscall(Syscall::kOpen);
    fd = dir >= 0 ? ::openat(dir, full.c_str() + slash + 1, kFlags) : ::open(full.c_str(), kFlags);
  } while (fd < 0 && errno == EINTR);
  if (fd < 0 && dir >= 0 && errno == ENOENT) {
    // The kept descriptor names the directory as it was when first kept: if it has been replaced since (a
    // scene folder swapped in place), the path may exist in the new one. Only a miss pays this second open.
    do {
      count_syscall(Syscall::kOpen);
      fd = ::open(full.c_str(), kFlags);
    } while (fd < 0 && errno == EINTR);
  }
  if (fd < 0) {
    const int err = errno;
    const ErrorCode code = (err == ENOENT || err == ENOTDIR) ? ErrorCode::kNotFound : ErrorCode::kIo;
    return make_error(code, "cannot open '" + full + "': " + std::strerror(err));
  }
  return std::unique_ptr<StorageFile>(new PosixFile(fd, full));
}

}  // namespace texstream::server
