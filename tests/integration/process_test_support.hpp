#pragma once
// Helpers for integration tests that run texstream executables as child processes: a fresh temp folder per
// test (named with the pid, so parallel ctest runs never share one), running a command with its output in a
// log file, and reading a file whole.
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace texstream::test {

// <tmp>/<prefix><name>_<pid>, emptied.
inline std::filesystem::path fresh_dir(const std::string& prefix, const std::string& name) {
  std::filesystem::path d = std::filesystem::temp_directory_path() / (prefix + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(d);
  std::filesystem::create_directories(d);
  return d;
}

// Runs `cmd` with stdout+stderr into `log`; returns the exit code (-1 if it did not exit normally).
inline int run_logged(const std::string& cmd, const std::filesystem::path& log) {
  const int status = std::system((cmd + " > '" + log.string() + "' 2>&1").c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace texstream::test
