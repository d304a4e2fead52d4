#include "texstream/server/storage/relative_path.hpp"

#include <fmt/format.h>

namespace texstream::server {

Result<std::string> relative_under(const std::filesystem::path& path, const std::filesystem::path& root) {
  const std::filesystem::path rel = path.lexically_normal().lexically_relative(root.lexically_normal());
  if (rel.empty() || *rel.begin() == ".." || rel == ".") {
    return make_error(ErrorCode::kInvalidArgument,
                      fmt::format("'{}' is not below the scene folder '{}'", path.string(), root.string()));
  }
  return rel.generic_string();
}

}  // namespace texstream::server
