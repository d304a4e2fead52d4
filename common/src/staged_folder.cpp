#include "texstream/common/staged_folder.hpp"

#include <unistd.h>

#include <string>

namespace texstream {

namespace fs = std::filesystem;

Result<StagedFolder> StagedFolder::create(const fs::path& destination, bool force, const char* kind) {
  const fs::path out = fs::absolute(destination).lexically_normal();
  std::error_code ec;
  if (fs::exists(out, ec) && !force && !fs::is_empty(out, ec))
    return make_error(ErrorCode::kInvalidArgument, out.string() + ": exists and is not empty (--force replaces it)");
  const fs::path parent = out.parent_path();
  fs::create_directories(parent, ec);
  // Built by appending: GCC 12 warns about "." + std::string with a false -Wrestrict.
  auto sibling = [&](const char* what) {
    std::string name(1, '.');
    name += out.filename().string();
    name += '.';
    name += what;
    name += '-';
    name += std::to_string(::getpid());
    return parent / name;
  };
  StagedFolder f(out, sibling(kind), sibling("old"));
  fs::remove_all(f.tmp_, ec);
  if (!fs::create_directories(f.tmp_ / "textures", ec))
    return make_error(ErrorCode::kIo, f.tmp_.string() + ": cannot create: " + ec.message());
  return f;
}

StagedFolder::StagedFolder(StagedFolder&& other) noexcept
    : out_(std::move(other.out_)),
      tmp_(std::move(other.tmp_)),
      old_(std::move(other.old_)),
      committed_(other.committed_) {
  other.committed_ = true;  // the moved-from object removes nothing
}

StagedFolder::~StagedFolder() {
  std::error_code ec;
  if (!committed_ && !tmp_.empty()) fs::remove_all(tmp_, ec);
}

Status StagedFolder::commit() {
  std::error_code ec;
  if (fs::exists(out_, ec)) {
    fs::rename(out_, old_, ec);
    if (ec) return make_error(ErrorCode::kIo, out_.string() + ": cannot move the old scene aside: " + ec.message());
  }
  fs::rename(tmp_, out_, ec);
  if (ec) {
    std::error_code back;
    if (fs::exists(old_, back)) fs::rename(old_, out_, back);
    return make_error(ErrorCode::kIo, out_.string() + ": cannot rename the new scene into place: " + ec.message());
  }
  committed_ = true;
  fs::remove_all(old_, ec);
  return ok_status();
}

}  // namespace texstream
