// texstream-render [--config FILE] [--set part.key=value]...
// Exit codes: 0 success; 1 a run-time failure (scene, device, I/O); 2 bad arguments or configuration;
// 5 the run finished but the Vulkan validation layer reported errors (tests rely on it).
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <string>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/render/renderer_app.hpp"

namespace {
constexpr int kExitFailure = 1;
constexpr int kExitBadArguments = 2;
constexpr int kExitValidationErrors = 5;
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"texstream-render: renders a texstream scene while streaming its textures from texstream-server"};
  std::string config_file;
  std::vector<std::string> overrides;
  app.add_option("--config", config_file, "TOML configuration file (default: built-in defaults)");
  app.add_option("--set", overrides, "Override one key: part.key=value (repeatable)")->take_all();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : kExitBadArguments;
  }

  auto config = texstream::load_config(config_file, overrides);
  if (!config) {
    std::fprintf(stderr, "texstream-render: %s\n", config.error().message.c_str());
    return kExitBadArguments;
  }
  if (auto valid = config->validate(); !valid) {
    std::fprintf(stderr, "texstream-render: %s\n", valid.error().message.c_str());
    return kExitBadArguments;
  }
  texstream::render::RenderRun run{*config, config_file, overrides};
  auto summary = texstream::render::run_renderer(run);
  if (!summary) {
    std::fprintf(stderr, "texstream-render: %s\n", summary.error().message.c_str());
    return summary.error().code == texstream::ErrorCode::kInvalidArgument ? kExitBadArguments : kExitFailure;
  }
  std::fputs(summary->to_text().c_str(), stdout);
  std::printf("output folder: %s\n", summary->output_dir.c_str());
  if (summary->validation_errors > 0) {
    std::fprintf(stderr, "texstream-render: %llu Vulkan validation error(s)\n",
                 static_cast<unsigned long long>(summary->validation_errors));
    return kExitValidationErrors;
  }
  return 0;
}
