#pragma once
// Request→completion latencies in microseconds, log-linear buckets (4 per power of two: ≤ 19 % relative
// error, HdrHistogram-style), so a histogram is a fixed 1 KiB whatever the run length. record() is lock-free
// (relaxed atomics: counters read for reports only); any thread may record and read (record_one_writer():
// one recording thread only).
#include <array>
#include <atomic>
#include <cstdint>

namespace texstream::server {

class LatencyHistogram {
 public:
  static constexpr uint32_t kSubBuckets = 4;
  static constexpr uint32_t kOctaves = 30;  // up to 2^32 µs (71 minutes): longer values land in the last bucket
  static constexpr uint32_t kBuckets = kSubBuckets + (kOctaves - 2) * kSubBuckets;

  void record(uint64_t micros);
  // record() for a histogram that only one thread ever records into (the server's dispatcher records both of
  // its histograms): plain loads and stores instead of read-modify-writes, which cost a locked instruction
  // each (four per hit, texstream-bench server's hit phase). Readers may take a snapshot at any time, as with
  // record(). Never mix with record() from another thread on the same histogram.
  void record_one_writer(uint64_t micros);
  uint64_t count() const { return count_.load(std::memory_order_relaxed); }
  uint64_t max_us() const { return max_.load(std::memory_order_relaxed); }
  double mean_us() const;
  // The upper bound of the bucket holding the p-th percentile (p in [0, 100]); 0 when empty.
  double percentile_us(double p) const;

  static uint32_t bucket_of(uint64_t micros);
  static uint64_t bucket_upper_us(uint32_t bucket);

 private:
  std::array<std::atomic<uint64_t>, kBuckets> buckets_{};
  std::atomic<uint64_t> count_{0};
  std::atomic<uint64_t> sum_{0};
  std::atomic<uint64_t> max_{0};
};

}  // namespace texstream::server
