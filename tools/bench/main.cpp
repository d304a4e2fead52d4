// texstream-bench: one executable, one CLI11 subcommand per benchmark (see bench_registry.hpp).
#include <cstdio>
#include <functional>
#include <utility>
#include <vector>

#include "bench_registry.hpp"

namespace texstream::bench {

namespace {
std::vector<Command>& registry() {
  static std::vector<Command> r;  // function-local: safe against static initialisation order
  return r;
}
}  // namespace

void register_command(const Command& command) { registry().push_back(command); }
const std::vector<Command>& commands() { return registry(); }

}  // namespace texstream::bench

int main(int argc, char** argv) {
  CLI::App app{"texstream-bench: one subcommand per benchmark; --quick finishes in about a minute"};
  app.require_subcommand(1);
  std::vector<std::pair<CLI::App*, std::function<int()>>> runs;
  for (const auto& c : texstream::bench::commands()) {
    CLI::App* sub = app.add_subcommand(c.name, c.help);
    runs.emplace_back(sub, c.define(*sub));
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    // Usage errors exit with 2, as before the subcommands were CLI11's (scripts and tests check it).
    app.exit(e);
    return 2;
  }
  for (auto& [sub, run] : runs) {
    if (sub->parsed()) return run();
  }
  return 2;
}
