// Every shader in shaders/ compiles (with each variant the renderer builds); include expansion, error
// locations in the original file and the SPIR-V disk cache behave.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "texstream/render/vulkan/shader_compiler.hpp"

namespace fs = std::filesystem;
using texstream::render::ShaderCompiler;
using texstream::render::ShaderRequest;
using texstream::render::ShaderStage;

namespace {

fs::path temp_dir(const std::string& name) {
  fs::path d = fs::temp_directory_path() / ("texstream_render_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

void write(const fs::path& p, const std::string& text) { std::ofstream(p) << text; }

}  // namespace

TEST(ShaderCompile, EveryShaderInTheFolderCompiles) {
  ShaderCompiler compiler(ShaderCompiler::default_source_dir(), {});
  int compiled = 0;
  for (const auto& entry : fs::directory_iterator(compiler.source_dir())) {
    const std::string ext = entry.path().extension().string();
    ShaderStage stage;
    if (ext == ".vert")
      stage = ShaderStage::kVertex;
    else if (ext == ".frag")
      stage = ShaderStage::kFragment;
    else if (ext == ".comp")
      stage = ShaderStage::kCompute;
    else
      continue;
    const std::string name = entry.path().filename().string();
    auto spirv = compiler.compile({name, stage, {}});
    ASSERT_TRUE(spirv.ok()) << spirv.error().message;
    EXPECT_EQ((*spirv)[0], 0x07230203u) << name;
    ++compiled;
  }
  EXPECT_GE(compiled, 3);
  // The wide metadata pass is scene.frag with WIDE_PASS.
  auto wide = compiler.compile({"scene.frag", ShaderStage::kFragment, {"WIDE_PASS"}});
  ASSERT_TRUE(wide.ok()) << wide.error().message;
}

TEST(ShaderCompile, ErrorsNameTheOriginalFileAndLine) {
  const fs::path dir = temp_dir("shader_err");
  write(dir / "main.frag", "#version 450\n#include \"inc.glsl\"\nvoid main() {}\n");
  write(dir / "inc.glsl", "// a helper\nfloat ok() { return 1.0; }\nfloat bad() { return undefined_name; }\n");
  ShaderCompiler compiler(dir, {});
  auto r = compiler.compile({"main.frag", ShaderStage::kFragment, {}});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("inc.glsl:3"), std::string::npos) << r.error().message;
  fs::remove_all(dir);
}

TEST(ShaderCompile, MissingIncludeIsNamed) {
  const fs::path dir = temp_dir("shader_inc");
  write(dir / "main.frag", "#version 450\n\n#include \"nope.glsl\"\nvoid main() {}\n");
  ShaderCompiler compiler(dir, {});
  auto r = compiler.compile({"main.frag", ShaderStage::kFragment, {}});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("main.frag:3"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("nope.glsl"), std::string::npos);
  fs::remove_all(dir);
}

TEST(ShaderCompile, IncludesExpandOnceAndDefinesFollowVersion) {
  const fs::path dir = temp_dir("shader_expand");
  write(dir / "main.frag", "#version 450\n#include \"a.glsl\"\n#include \"a.glsl\"\nvoid main() {}\n");
  write(dir / "a.glsl", "float a() { return 1.0; }\n");
  ShaderCompiler compiler(dir, {});
  auto e = compiler.expand("main.frag", {"FOO=3"});
  ASSERT_TRUE(e.ok()) << e.error().message;
  EXPECT_EQ(e->text, "#version 450\n#define FOO 3\nfloat a() { return 1.0; }\nvoid main() {}\n");
  ASSERT_EQ(e->origin.size(), 4u);
  EXPECT_EQ(e->origin[2].first, "a.glsl");
  EXPECT_EQ(e->origin[3].second, 4);
  fs::remove_all(dir);
}

TEST(ShaderCompile, SecondCompileComesFromTheCacheAndChangesMissIt) {
  const fs::path dir = temp_dir("shader_cache");
  write(dir / "main.comp", "#version 450\nlayout(local_size_x = 1) in;\nvoid main() {}\n");
  {
    ShaderCompiler c(dir, dir / "cache");
    ASSERT_TRUE(c.compile({"main.comp", ShaderStage::kCompute, {}}).ok());
    EXPECT_EQ(c.compiled(), 1u);
    EXPECT_EQ(c.cache_hits(), 0u);
  }
  {
    ShaderCompiler c(dir, dir / "cache");
    auto again = c.compile({"main.comp", ShaderStage::kCompute, {}});
    ASSERT_TRUE(again.ok());
    EXPECT_EQ(c.cache_hits(), 1u);
    EXPECT_EQ(c.compiled(), 0u);
    // A define changes the hash: compiled anew.
    ASSERT_TRUE(c.compile({"main.comp", ShaderStage::kCompute, {"X"}}).ok());
    EXPECT_EQ(c.compiled(), 1u);
  }
  fs::remove_all(dir);
}

TEST(ShaderCompile, ASharedStructsHeaderThatDiffersFromTheBuildIsRefused) {
  // The renderer's C++ was compiled with shaders/shared_structs.h; GLSL is compiled at run time from disk. A
  // header edited after the build would silently change one side's layout: the compiler must refuse it.
  const fs::path dir = temp_dir("shader_structs");
  const fs::path src = ShaderCompiler::default_source_dir();
  for (const auto& entry : fs::directory_iterator(src)) fs::copy(entry.path(), dir / entry.path().filename());
  {
    ShaderCompiler same(dir, {});
    auto ok = same.compile({"compact.comp", ShaderStage::kCompute, {}});
    ASSERT_TRUE(ok.ok()) << ok.error().message;
  }
  std::ofstream(dir / "shared_structs.h", std::ios::app) << "\n// edited after the build\n";
  ShaderCompiler changed(dir, {});
  auto r = changed.compile({"compact.comp", ShaderStage::kCompute, {}});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("shared_structs.h differs"), std::string::npos) << r.error().message;
  fs::remove_all(dir);
}
