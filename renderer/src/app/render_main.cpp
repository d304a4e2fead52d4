// The command line of texstream-render [--config FILE] [--set part.key=value]...
// Exit codes: 0 success; 1 a run-time failure (scene, device, I/O); 2 bad arguments or configuration;
// 5 the run finished but the Vulkan validation layer reported errors (tests rely on it).
#include <CLI/CLI.hpp>

#include <cstdio>
#include <string>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/render/app/renderer_app.hpp"

namespace texstream::render {

namespace {
constexpr int kExitFailure = 1;
constexpr int kExitBadArguments = 2;
constexpr int kExitValidationErrors = 5;
}  // namespace

int render_main(int argc, char** argv, const char* program, InProcessServerFactory in_process_server) {
  CLI::App app{std::string(program) + ": renders a texstream scene while streaming its textures from texstream-server" +
               (in_process_server ? " (run in a thread of this process)" : "")};
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

  auto config = load_config(config_file, overrides);
  if (!config) {
    std::fprintf(stderr, "%s: %s\n", program, config.error().message.c_str());
    return kExitBadArguments;
  }
  if (auto valid = config->validate(); !valid) {
    std::fprintf(stderr, "%s: %s\n", program, valid.error().message.c_str());
    return kExitBadArguments;
  }
  RenderRun run{*config, config_file, overrides, std::move(in_process_server)};
  auto summary = run_renderer(run);
  if (!summary) {
    std::fprintf(stderr, "%s: %s\n", program, summary.error().message.c_str());
    return summary.error().code == ErrorCode::kInvalidArgument ? kExitBadArguments : kExitFailure;
  }
  std::fputs(summary->to_text().c_str(), stdout);
  std::printf("output folder: %s\n", summary->output_dir.c_str());
  if (summary->validation_errors > 0) {
    std::fprintf(stderr, "%s: %llu Vulkan validation error(s)\n", program,
                 static_cast<unsigned long long>(summary->validation_errors));
    return kExitValidationErrors;
  }
  return 0;
}

}  // namespace texstream::render
