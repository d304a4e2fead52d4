#pragma once
// Small helpers every benchmark uses: percentiles, the summary line, and a monotonic stopwatch.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace texstream::bench {

// The folder of the running texstream-bench: the other programs a benchmark starts are built beside it.
inline std::filesystem::path self_dir() {
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::filesystem::path(".") : exe.parent_path();
}

// p in [0, 100]; nearest-rank on a sorted copy. Empty input gives 0.
inline double percentile(std::vector<double> values, double p) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const double rank = p / 100.0 * static_cast<double>(values.size() - 1);
  const size_t lo = static_cast<size_t>(rank);
  const size_t hi = std::min(lo + 1, values.size() - 1);
  const double frac = rank - static_cast<double>(lo);
  return values[lo] * (1.0 - frac) + values[hi] * frac;
}

inline double mean(const std::vector<double>& values) {
  if (values.empty()) return 0.0;
  double sum = 0;
  for (double v : values) sum += v;
  return sum / static_cast<double>(values.size());
}

// Prints `summary: k1=v1 k2=v2 ...` as the last line of a benchmark (keys are read by tooling: keep them stable).
class Summary {
 public:
  Summary& add(const std::string& key, double value) {
    char buf[64];
    // Counts print as integers (stress_sequences=1000000, not 1e+06); everything else with 6 significant digits.
    if (std::isfinite(value) && std::floor(value) == value && std::fabs(value) < 1e15) {
      std::snprintf(buf, sizeof buf, "%.0f", value);
    } else {
      std::snprintf(buf, sizeof buf, "%.6g", value);
    }
    items_.emplace_back(key, buf);
    return *this;
  }
  Summary& add(const std::string& key, const std::string& value) {
    items_.emplace_back(key, value);
    return *this;
  }
  Summary& add_bool(const std::string& key, bool value) { return add(key, std::string(value ? "true" : "false")); }
  void print() const {
    std::string line = "summary:";
    for (const auto& [k, v] : items_) line += " " + k + "=" + v;
    std::printf("%s\n", line.c_str());
    std::fflush(stdout);
  }

 private:
  std::vector<std::pair<std::string, std::string>> items_;
};

class Stopwatch {
 public:
  Stopwatch() : t0_(std::chrono::steady_clock::now()) {}
  double seconds() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count(); }
  double micros() const { return seconds() * 1e6; }
  void reset() { t0_ = std::chrono::steady_clock::now(); }

 private:
  std::chrono::steady_clock::time_point t0_;
};

inline bool has_flag(const std::vector<std::string>& args, const std::string& flag) {
  return std::find(args.begin(), args.end(), flag) != args.end();
}

}  // namespace texstream::bench
