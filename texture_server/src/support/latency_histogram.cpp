#include "texstream/server/support/latency_histogram.hpp"

#include <algorithm>
#include <cmath>

namespace texstream::server {

uint32_t LatencyHistogram::bucket_of(uint64_t v) {
  if (v < kSubBuckets) return static_cast<uint32_t>(v);  // 0..3 µs exactly
  const uint32_t octave = 63u - static_cast<uint32_t>(__builtin_clzll(v));  // >= 2
  if (octave >= kOctaves) return kBuckets - 1;
  const uint32_t sub = static_cast<uint32_t>(v >> (octave - 2)) & (kSubBuckets - 1);
  return kSubBuckets + (octave - 2) * kSubBuckets + sub;
}

uint64_t LatencyHistogram::bucket_upper_us(uint32_t bucket) {
  if (bucket < kSubBuckets) return bucket;
  const uint32_t octave = 2 + (bucket - kSubBuckets) / kSubBuckets;
  const uint64_t sub = (bucket - kSubBuckets) % kSubBuckets;
  return ((kSubBuckets + sub + 1) << (octave - 2)) - 1;
}

void LatencyHistogram::record(uint64_t micros) {
  // relaxed everywhere: independent statistics, no data published through them.
  buckets_[bucket_of(micros)].fetch_add(1, std::memory_order_relaxed);
  count_.fetch_add(1, std::memory_order_relaxed);
  sum_.fetch_add(micros, std::memory_order_relaxed);
  uint64_t seen = max_.load(std::memory_order_relaxed);
  while (micros > seen && !max_.compare_exchange_weak(seen, micros, std::memory_order_relaxed)) {
  }
}

void LatencyHistogram::record_one_writer(uint64_t micros) {
  // relaxed everywhere: independent statistics; this thread is the only writer, so load + store loses nothing.
  const auto bump = [](std::atomic<uint64_t>& a, uint64_t v) {
    a.store(a.load(std::memory_order_relaxed) + v, std::memory_order_relaxed);
  };
  bump(buckets_[bucket_of(micros)], 1);
  bump(count_, 1);
  bump(sum_, micros);
  if (micros > max_.load(std::memory_order_relaxed)) max_.store(micros, std::memory_order_relaxed);
}

double LatencyHistogram::mean_us() const {
  const uint64_t n = count();
  return n == 0 ? 0.0 : static_cast<double>(sum_.load(std::memory_order_relaxed)) / static_cast<double>(n);
}

double LatencyHistogram::percentile_us(double p) const {
  uint64_t total = 0;
  std::array<uint64_t, kBuckets> snapshot{};
  for (uint32_t i = 0; i < kBuckets; ++i) total += snapshot[i] = buckets_[i].load(std::memory_order_relaxed);
  if (total == 0) return 0.0;
  // Nearest rank: the smallest bucket whose cumulative count reaches ceil(p/100 * total).
  const uint64_t rank = std::max<uint64_t>(1, static_cast<uint64_t>(std::ceil(std::clamp(p, 0.0, 100.0) / 100.0 *
                                                                               static_cast<double>(total))));
  uint64_t seen = 0;
  for (uint32_t i = 0; i < kBuckets; ++i) {
    seen += snapshot[i];
    if (seen >= rank) return static_cast<double>(std::min(bucket_upper_us(i), max_us()));
  }
  return static_cast<double>(max_us());
}

}  // namespace texstream::server
