// texstream-bench: one executable, one subcommand per benchmark (see bench_registry.hpp).
#include <cstdio>
#include <cstring>
#include <string>
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
  using texstream::bench::commands;
  auto usage = [] {
    std::fprintf(stderr, "usage: texstream-bench <command> [--quick] [options]\ncommands:\n");
    for (const auto& c : commands()) std::fprintf(stderr, "  %-12s %s\n", c.name, c.help);
  };
  if (argc < 2 || std::strcmp(argv[1], "--help") == 0 || std::strcmp(argv[1], "-h") == 0) {
    usage();
    return argc < 2 ? 2 : 0;
  }
  for (const auto& c : commands()) {
    if (std::strcmp(argv[1], c.name) == 0) return c.run(std::vector<std::string>(argv + 2, argv + argc));
  }
  std::fprintf(stderr, "texstream-bench: unknown command '%s'\n", argv[1]);
  usage();
  return 2;
}
