#pragma once
// A one-line progress bar on stderr for the command-line tools, redrawn at most every 200 ms; safe to call from
// worker threads.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <mutex>
#include <string>

namespace texstream {

class ProgressBar {
 public:
  explicit ProgressBar(std::string noun = "textures") : noun_(std::move(noun)) {}

  void update(uint64_t done, uint64_t total) {
    std::lock_guard lock(mutex_);
    const auto now = std::chrono::steady_clock::now();
    if (done < total && now - last_ < std::chrono::milliseconds(200)) return;
    last_ = now;
    const double elapsed = std::chrono::duration<double>(now - start_).count();
    const double rate = elapsed > 0 ? static_cast<double>(done) / elapsed : 0.0;
    const int width = 30, filled = static_cast<int>(width * done / std::max<uint64_t>(total, 1));
    std::fprintf(stderr, "\r[%.*s%*s] %llu/%llu %s  %.0f/s  ETA %.0f s   ", filled, "##############################",
                 width - filled, "", static_cast<unsigned long long>(done), static_cast<unsigned long long>(total),
                 noun_.c_str(), rate, rate > 0 ? static_cast<double>(total - done) / rate : 0.0);
    if (done >= total) std::fprintf(stderr, "\n");
  }

 private:
  std::string noun_;
  std::mutex mutex_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point last_{};
};

}  // namespace texstream
