#include "texstream/server/storage/token_bucket.hpp"

#include <algorithm>

#include "texstream/common/contract.hpp"

namespace texstream::server {

TokenBucket::TokenBucket(double bytes_per_s, double burst_bytes)
    : rate_per_ns_(bytes_per_s / 1e9), burst_(burst_bytes), tokens_(burst_bytes) {
  TS_ASSERT(bytes_per_s > 0 && burst_bytes > 0, "token bucket needs a positive rate and burst");
}

uint64_t TokenBucket::take(uint64_t bytes, uint64_t now_ns) {
  std::lock_guard lock(mutex_);
  if (started_ && now_ns > last_ns_) {
    tokens_ = std::min(burst_, tokens_ + static_cast<double>(now_ns - last_ns_) * rate_per_ns_);
  }
  if (!started_ || now_ns > last_ns_) last_ns_ = now_ns;
  started_ = true;
  tokens_ -= static_cast<double>(bytes);
  return tokens_ >= 0 ? 0 : static_cast<uint64_t>(-tokens_ / rate_per_ns_);
}

}  // namespace texstream::server
