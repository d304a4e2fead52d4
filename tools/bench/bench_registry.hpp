#pragma once
// texstream-bench subcommands register themselves here, one file each (server_bench.cpp, controller_bench.cpp,
// ...), so parts can add benchmarks without touching main.cpp. Each declares its flags on its CLI11
// subcommand; every subcommand accepts --quick (finishes in 60 s on the 2-core machine) and ends its output
// with exactly one line `summary: key=value ...`.
#include <functional>
#include <vector>

#include <CLI/CLI.hpp>

namespace texstream::bench {

struct Command {
  const char* name;
  const char* help;
  // Declares the subcommand's flags on `app`, bound to options it keeps, and returns what runs once they are
  // parsed (its exit code).
  std::function<int()> (*define)(CLI::App& app);
};

void register_command(const Command& command);
const std::vector<Command>& commands();

struct Registrar {
  explicit Registrar(const Command& command) { register_command(command); }
};

}  // namespace texstream::bench

// In a subcommand's .cpp: TEXSTREAM_BENCH_COMMAND(server, "RAM cache and exact-read throughput", define_server);
#define TEXSTREAM_BENCH_COMMAND(id, help, fn) \
  static const ::texstream::bench::Registrar texstream_bench_registrar_##id({#id, help, fn})
