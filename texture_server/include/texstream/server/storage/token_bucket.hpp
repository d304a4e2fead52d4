#pragma once
// A token bucket over bytes (server.rate_limit_mb_s, seed 002 §3.3: texture is a bandwidth-limited resource,
// so the server must not take all of the storage bandwidth or CPU from the renderer). Tokens accrue at
// `bytes_per_s` up to `burst_bytes`; take(n) removes n tokens and says how long the caller must wait before
// its read may start. A read larger than the burst is allowed and simply waits longer (the balance goes
// negative), so any size is served and the long-run rate is exact. No clock inside: the caller passes
// `now_ns` (tests use a fake clock). Thread-safe.
#include <cstdint>
#include <mutex>

namespace texstream::server {

class TokenBucket {
 public:
  TokenBucket(double bytes_per_s, double burst_bytes);
  // Nanoseconds to wait before reading `bytes` that are taken at `now_ns` (0 = go now).
  uint64_t take(uint64_t bytes, uint64_t now_ns);

 private:
  const double rate_per_ns_;
  const double burst_;
  std::mutex mutex_;
  double tokens_;
  uint64_t last_ns_ = 0;
  bool started_ = false;
};

}  // namespace texstream::server
