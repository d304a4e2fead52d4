#pragma once
// A scene folder written beside its destination and renamed into place when complete, so that a tool that
// fails half-way (texstream-import, texstream-atlas) leaves nothing half written and the previous folder as it
// was. The staging folder is a hidden sibling (".NAME.KIND-PID"), on the same file system as the destination.
#include <filesystem>

#include "texstream/common/result.hpp"

namespace texstream {

class StagedFolder {
 public:
  // Refuses a non-empty `out` unless `force` (the message names --force); creates the staging folder with a
  // `textures/` subfolder. `kind` names the tool in the staging folder's name ("import", "atlas").
  static Result<StagedFolder> create(const std::filesystem::path& out, bool force, const char* kind);
  StagedFolder(StagedFolder&& other) noexcept;
  StagedFolder& operator=(StagedFolder&&) = delete;
  StagedFolder(const StagedFolder&) = delete;
  ~StagedFolder();  // removes the staging folder unless commit() succeeded

  const std::filesystem::path& dir() const { return tmp_; }
  // Moves a previous `out` aside, renames the staging folder to `out`, then removes the old one; on a failed
  // rename the old folder is put back.
  Status commit();

 private:
  StagedFolder(std::filesystem::path out, std::filesystem::path tmp, std::filesystem::path old)
      : out_(std::move(out)), tmp_(std::move(tmp)), old_(std::move(old)) {}
  std::filesystem::path out_, tmp_, old_;
  bool committed_ = false;
};

}  // namespace texstream
