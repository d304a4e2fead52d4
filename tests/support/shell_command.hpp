#pragma once
// Running one of our programs from a test as a user would, through the shell, and reading what it printed.
#include <sys/wait.h>

#include <cstdio>
#include <sstream>
#include <string>

namespace texstream::test {

// Runs `cmd` through the shell; returns its exit code (-1 if it did not exit) and what it printed on stdout and
// stderr together into `output` (when given).
inline int run_command(const std::string& cmd, std::string* output) {
  std::string out;
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  if (!p) return -1;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  const int rc = pclose(p);
  if (output) *output = out;
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

// The last non-empty line: a benchmark's `summary:` line.
inline std::string last_line(const std::string& text) {
  std::istringstream in(text);
  std::string line, last;
  while (std::getline(in, line))
    if (!line.empty()) last = line;
  return last;
}

}  // namespace texstream::test
