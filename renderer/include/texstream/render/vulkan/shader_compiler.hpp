#pragma once
// GLSL -> SPIR-V at start-up with the glslang library (Granite compiler.hpp style): `#include "x"` is expanded
// here (each file once), the expanded source plus stage and defines is hashed, and the SPIR-V is cached on disk
// under that hash. Errors name the original file and line, not the line in the expanded text.
#include <cstdint>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "texstream/common/result.hpp"

namespace texstream::render {

enum class ShaderStage { kVertex, kFragment, kCompute };

struct ShaderRequest {
  std::string file;  // relative to the source dir, e.g. "scene.frag"
  ShaderStage stage;
  std::vector<std::string> defines;  // "NAME" or "NAME=VALUE"
};

// The include-expanded text and, for each of its lines, where it came from.
struct ExpandedSource {
  std::string text;
  std::vector<std::pair<std::string, int>> origin;  // origin[i] = (file, 1-based line) of expanded line i + 1
};

class ShaderCompiler {
 public:
  // `cache_dir` empty: no disk cache.
  ShaderCompiler(std::filesystem::path source_dir, std::filesystem::path cache_dir);

  // env TEXSTREAM_SHADER_DIR, else the source folder this build was configured from.
  static std::filesystem::path default_source_dir();
  // env TEXSTREAM_SPIRV_CACHE, else $XDG_CACHE_HOME/texstream/spirv, else ~/.cache/texstream/spirv; empty if
  // none of these can be named.
  static std::filesystem::path default_cache_dir();

  Result<std::vector<uint32_t>> compile(const ShaderRequest& request);
  // Expands includes of `file`; `defines` go right after the #version line.
  Result<ExpandedSource> expand(const std::string& file, const std::vector<std::string>& defines) const;

  const std::filesystem::path& source_dir() const { return source_dir_; }
  uint32_t cache_hits() const { return cache_hits_; }
  uint32_t compiled() const { return compiled_; }

 private:
  std::filesystem::path source_dir_;
  std::filesystem::path cache_dir_;
  uint32_t cache_hits_ = 0;
  uint32_t compiled_ = 0;
};

}  // namespace texstream::render
