#pragma once
// Storage on the local file system: open(2) + pread(2) of exactly the asked range. Never reads a whole file.
#include <cstddef>
#include <functional>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>

#include "texstream/server/storage/storage.hpp"

namespace texstream::server {

//
// Files are opened relative to a kept descriptor of their directory (openat): a scene's textures share a few
// directories, and resolving the whole path again on every open was ~1/3 of open()'s cost, which was the
// dispatcher's largest cost after the reads (texstream-bench server, misses, perf: path walk and dentry
// lookups). At most kMaxDirectories are kept (the rest open by full path); a directory that cannot be opened
// is not remembered (it may appear later) and its files are opened by full path, so errors read as before.
// Directories are assumed not to be replaced while the server runs (as the files, texture_file_index.hpp).
// Thread-safe.
class PosixStorage final : public Storage {
 public:
  // 4096 textures per directory (scene_format.hpp): 64 directories cover scenes of 256 K textures.
  static constexpr size_t kMaxDirectories = 64;

  PosixStorage() = default;
  ~PosixStorage() override;
  PosixStorage(const PosixStorage&) = delete;
  PosixStorage& operator=(const PosixStorage&) = delete;

  Result<std::unique_ptr<StorageFile>> open(const std::filesystem::path& path) override;
  Result<std::unique_ptr<StorageFile>> open_text(const std::string& path) override;
  // A file opened by its first read, which with io_uring (UringReader) opens, reads and closes it in one
  // submission; every read does so again, so a kept file holds no descriptor. Without io_uring, or for what
  // the page cache cannot give at once, the file is opened the ordinary way and reads with pread.
  Result<std::unique_ptr<StorageFile>> open_lazy(const std::string& path) override;
  size_t directories_kept() const;

 private:
  struct Hash {
    using is_transparent = void;
    size_t operator()(std::string_view s) const { return std::hash<std::string_view>{}(s); }
  };
  // The kept descriptor of `dir`, opened now if there is room; -1 if it cannot be opened or there is none.
  int directory_fd(std::string_view dir);

  mutable std::mutex mutex_;
  std::unordered_map<std::string, int, Hash, std::equal_to<>> dirs_;
};

}  // namespace texstream::server
