#pragma once
// Storage on the local file system: open(2) + pread(2) of exactly the asked range. Never reads a whole file.
#include "texstream/server/storage.hpp"

namespace texstream::server {

class PosixStorage final : public Storage {
 public:
  Result<std::unique_ptr<StorageFile>> open(const std::filesystem::path& path) override;
};

}  // namespace texstream::server
