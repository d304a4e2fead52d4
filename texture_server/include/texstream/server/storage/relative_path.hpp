#pragma once
// The part of a file's path below the scene folder: how the http origin builds URLs and the disk cache builds
// keys, so both are independent of where the local scene folder happens to be.
#include <filesystem>
#include <string>

#include "texstream/common/result.hpp"

namespace texstream::server {

// "textures/000/00000001.dds" for <root>/textures/000/00000001.dds (generic '/' separators). Errors:
// kInvalidArgument when `path` is not below `root`, naming both.
Result<std::string> relative_under(const std::filesystem::path& path, const std::filesystem::path& root);

}  // namespace texstream::server
