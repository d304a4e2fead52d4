#include "texstream/render/vulkan/shader_compiler.hpp"

#include <glslang/Public/ResourceLimits.h>
#include <glslang/Public/ShaderLang.h>
#include <glslang/SPIRV/GlslangToSpv.h>
#include <glslang/build_info.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <mutex>
#include <optional>
#include <regex>
#include <set>
#include <sstream>

#include "texstream/protocol/checksum.hpp"
#include "texstream/shared_structs_embedded.hpp"

namespace texstream::render {

namespace fs = std::filesystem;

namespace {

// Bumped when the way we call glslang changes (options, target), so stale cache entries are not reused.
constexpr const char* kCompilerTag = "texstream-glslang-1";
constexpr uint32_t kSpirvMagic = 0x07230203;

Result<std::string> read_text(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return make_error(ErrorCode::kNotFound, "shader source " + path.string() + ": cannot open");
  std::ostringstream s;
  s << in.rdbuf();
  if (in.bad()) return make_error(ErrorCode::kIo, "shader source " + path.string() + ": read failed");
  return s.str();
}

struct Expander {
  const fs::path& root;
  std::set<fs::path> seen;
  ExpandedSource out;

  Status add(const fs::path& path, const std::string& display, int depth) {
    if (depth > 16) return make_error(ErrorCode::kInvalidArgument, display + ": includes nested deeper than 16");
    const fs::path canonical = fs::weakly_canonical(path);
    if (!seen.insert(canonical).second) return ok_status();  // every file once (#pragma once semantics)
    auto text = read_text(path);
    if (!text) return text.error();
    if (path.filename() == "shared_structs.h" && *text != kSharedStructsSource) {
      return make_error(ErrorCode::kInvalidArgument,
                        path.string() +
                            " differs from the shared_structs.h texstream-render was built with: C++ and "
                            "GLSL would disagree on struct layouts; rebuild (cmake --build build)");
    }
    static const std::regex include_re(R"(^\s*#\s*include\s*"([^"]+)\"\s*$)");
    std::istringstream lines(*text);
    std::string line;
    int number = 0;
    while (std::getline(lines, line)) {
      ++number;
      std::smatch m;
      if (std::regex_match(line, m, include_re)) {
        fs::path target = path.parent_path() / m[1].str();
        if (!fs::exists(target)) target = root / m[1].str();
        if (!fs::exists(target)) {
          return make_error(ErrorCode::kNotFound,
                            display + ":" + std::to_string(number) + ": include \"" + m[1].str() + "\" not found");
        }
        TS_TRY(add(target, m[1].str(), depth + 1));
        continue;
      }
      out.text += line + "\n";
      out.origin.emplace_back(display, number);
    }
    return ok_status();
  }
};

EShLanguage to_glslang(ShaderStage s) {
  switch (s) {
    case ShaderStage::kVertex:
      return EShLangVertex;
    case ShaderStage::kFragment:
      return EShLangFragment;
    case ShaderStage::kCompute:
      return EShLangCompute;
  }
  TS_UNREACHABLE("stage %d", static_cast<int>(s));
}

// "ERROR: 0:12: ..." -> "ERROR: scene.frag:40: ..." through the expansion's line map.
std::string map_log(const std::string& log, const ExpandedSource& src) {
  static const std::regex loc_re(R"((ERROR|WARNING): 0:(\d+):)");
  std::string out;
  auto begin = log.cbegin();
  std::smatch m;
  while (std::regex_search(begin, log.cend(), m, loc_re)) {
    out.append(begin, m[0].first);
    const size_t line = std::stoul(m[2].str());
    if (line >= 1 && line <= src.origin.size()) {
      const auto& [file, original] = src.origin[line - 1];
      out += m[1].str() + ": " + file + ":" + std::to_string(original) + ":";
    } else {
      out += m[0].str();
    }
    begin = m[0].second;
  }
  out.append(begin, log.cend());
  return out;
}

std::optional<std::vector<uint32_t>> read_cached(const fs::path& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return std::nullopt;
  const auto size = static_cast<size_t>(in.tellg());
  if (size < 20 || size % 4 != 0) return std::nullopt;  // 5-word SPIR-V header at least
  std::vector<uint32_t> words(size / 4);
  in.seekg(0);
  if (!in.read(reinterpret_cast<char*>(words.data()), static_cast<std::streamsize>(size))) return std::nullopt;
  if (words[0] != kSpirvMagic) return std::nullopt;
  return words;
}

void write_cached(const fs::path& dir, const fs::path& path, const std::vector<uint32_t>& words) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return;  // a cache we cannot write is only slower
  // Written under a unique name, then renamed: concurrent renderers never see half a file.
  const fs::path tmp = path.string() + ".tmp" + std::to_string(::getpid());
  {
    std::ofstream out(tmp, std::ios::binary);
    out.write(reinterpret_cast<const char*>(words.data()), static_cast<std::streamsize>(words.size() * 4));
    if (!out) {
      fs::remove(tmp, ec);
      return;
    }
  }
  fs::rename(tmp, path, ec);
  if (ec) fs::remove(tmp, ec);
}

}  // namespace

ShaderCompiler::ShaderCompiler(fs::path source_dir, fs::path cache_dir)
    : source_dir_(std::move(source_dir)), cache_dir_(std::move(cache_dir)) {}

fs::path ShaderCompiler::default_source_dir() {
  if (const char* env = std::getenv("TEXSTREAM_SHADER_DIR"); env && *env) return env;
  return TEXSTREAM_SHADER_DIR;
}

fs::path ShaderCompiler::default_cache_dir() {
  if (const char* env = std::getenv("TEXSTREAM_SPIRV_CACHE"); env && *env) return env;
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg) return fs::path(xdg) / "texstream" / "spirv";
  if (const char* home = std::getenv("HOME"); home && *home) return fs::path(home) / ".cache" / "texstream" / "spirv";
  return {};
}

Result<ExpandedSource> ShaderCompiler::expand(const std::string& file, const std::vector<std::string>& defines) const {
  Expander e{source_dir_, {}, {}};
  TS_TRY(e.add(source_dir_ / file, file, 0));
  if (e.out.origin.empty() || e.out.text.rfind("#version", 0) != 0) {
    return make_error(ErrorCode::kInvalidArgument, file + ":1: the first line must be #version");
  }
  // Defines go after the #version line; their lines are attributed to the command line.
  const size_t eol = e.out.text.find('\n') + 1;
  std::string inject;
  std::vector<std::pair<std::string, int>> origins;
  for (const auto& d : defines) {
    const auto eq = d.find('=');
    inject += "#define " + (eq == std::string::npos ? d + " 1" : d.substr(0, eq) + " " + d.substr(eq + 1)) + "\n";
    origins.emplace_back("<define " + d + ">", 1);
  }
  e.out.text.insert(eol, inject);
  e.out.origin.insert(e.out.origin.begin() + 1, origins.begin(), origins.end());
  return std::move(e.out);
}

Result<std::vector<uint32_t>> ShaderCompiler::compile(const ShaderRequest& request) {
  auto expanded = expand(request.file, request.defines);
  if (!expanded) return expanded.error();

  std::string key_text = expanded->text;
  key_text += "\n//stage " + std::to_string(static_cast<int>(request.stage)) + " " + kCompilerTag + " glslang " +
              std::to_string(GLSLANG_VERSION_MAJOR) + "." + std::to_string(GLSLANG_VERSION_MINOR) + "." +
              std::to_string(GLSLANG_VERSION_PATCH);
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx",
                static_cast<unsigned long long>(payload_checksum(key_text.data(), key_text.size())));
  const fs::path cached = cache_dir_.empty() ? fs::path() : cache_dir_ / (std::string(hex) + ".spv");
  if (!cached.empty()) {
    if (auto words = read_cached(cached)) {
      ++cache_hits_;
      return std::move(*words);
    }
  }

  static std::once_flag init;
  std::call_once(init, [] { glslang::InitializeProcess(); });

  const EShLanguage lang = to_glslang(request.stage);
  glslang::TShader shader(lang);
  const char* text = expanded->text.c_str();
  // No string name: glslang then reports "0:<line>", which map_log turns into the original file and line.
  shader.setStrings(&text, 1);
  shader.setEnvInput(glslang::EShSourceGlsl, lang, glslang::EShClientVulkan, 100);
  shader.setEnvClient(glslang::EShClientVulkan, glslang::EShTargetVulkan_1_2);
  shader.setEnvTarget(glslang::EShTargetSpv, glslang::EShTargetSpv_1_5);
  const auto messages = static_cast<EShMessages>(EShMsgSpvRules | EShMsgVulkanRules);
  if (!shader.parse(GetDefaultResources(), 450, false, messages)) {
    return make_error(ErrorCode::kInvalidArgument,
                      "shader " + request.file + " failed to compile:\n" + map_log(shader.getInfoLog(), *expanded));
  }
  glslang::TProgram program;
  program.addShader(&shader);
  if (!program.link(messages)) {
    return make_error(ErrorCode::kInvalidArgument,
                      "shader " + request.file + " failed to link:\n" + map_log(program.getInfoLog(), *expanded));
  }
  std::vector<uint32_t> spirv;
  glslang::SpvOptions options;
  options.generateDebugInfo = false;
  options.disableOptimizer = false;
  glslang::GlslangToSpv(*program.getIntermediate(lang), spirv, &options);
  if (spirv.empty()) return make_error(ErrorCode::kInvalidArgument, "shader " + request.file + ": no SPIR-V produced");
  ++compiled_;
  if (!cached.empty()) write_cached(cache_dir_, cached, spirv);
  return spirv;
}

}  // namespace texstream::render
