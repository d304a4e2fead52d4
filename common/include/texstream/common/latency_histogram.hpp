#pragma once
// One histogram for every latency the project reports: the server's request→completion times (µs) and the
// renderer's IPC time per frame (ns). Log-linear buckets, HdrHistogram-style: values below 2^SubBucketBits
// units have a bucket each; above, each power of two is split into 2^SubBucketBits buckets (relative error
// ≤ 2^-SubBucketBits); values at or past 2^Octaves units share the last bucket. The count, sum and maximum
// are exact, in the values as recorded; only the buckets are in units of `Unit` recorded values.
//
// record() is lock-free (relaxed atomics: counters read for reports only); any thread may record and read.
// record_one_writer(): for a histogram that only one thread ever records into.
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>

namespace texstream {

template <uint32_t SubBucketBits, uint32_t Octaves, uint64_t Unit = 1>
class LogLinearHistogram {
  static_assert(SubBucketBits >= 1 && SubBucketBits <= Octaves && Octaves < 64 && Unit >= 1);

 public:
  static constexpr uint32_t kSubBuckets = 1u << SubBucketBits;
  static constexpr uint32_t kOctaves = Octaves;
  static constexpr uint32_t kBuckets = kSubBuckets + (kOctaves - SubBucketBits) * kSubBuckets;
  static constexpr uint64_t kUnit = Unit;

  void record(uint64_t value) {
    // relaxed everywhere: independent statistics, no data published through them.
    buckets_[bucket_of(value / Unit)].fetch_add(1, std::memory_order_relaxed);
    count_.fetch_add(1, std::memory_order_relaxed);
    sum_.fetch_add(value, std::memory_order_relaxed);
    uint64_t seen = max_.load(std::memory_order_relaxed);
    while (value > seen && !max_.compare_exchange_weak(seen, value, std::memory_order_relaxed)) {
    }
  }
  // record() for a histogram that only one thread ever records into (the server's dispatcher records both of
  // its histograms): plain loads and stores instead of read-modify-writes, which cost a locked instruction
  // each (four per hit, texstream-bench server's hit phase). Readers may take a snapshot at any time, as with
  // record(). Never mix with record() from another thread on the same histogram.
  void record_one_writer(uint64_t value) {
    // relaxed everywhere: independent statistics; this thread is the only writer, so load + store loses nothing.
    const auto bump = [](std::atomic<uint64_t>& a, uint64_t v) {
      a.store(a.load(std::memory_order_relaxed) + v, std::memory_order_relaxed);
    };
    bump(buckets_[bucket_of(value / Unit)], 1);
    bump(count_, 1);
    bump(sum_, value);
    if (value > max_.load(std::memory_order_relaxed)) max_.store(value, std::memory_order_relaxed);
  }

  uint64_t count() const { return count_.load(std::memory_order_relaxed); }
  uint64_t max() const { return max_.load(std::memory_order_relaxed); }
  uint64_t sum() const { return sum_.load(std::memory_order_relaxed); }
  double mean() const {
    const uint64_t n = count();
    return n == 0 ? 0.0 : static_cast<double>(sum()) / static_cast<double>(n);
  }
  // The largest value the bucket holding the p-th percentile (p in [0, 100]) can hold, at most the maximum
  // seen; 0 when empty.
  double percentile(double p) const {
    // Nearest rank: the smallest bucket whose cumulative count reaches ceil(p/100 * total).
    return rank_value(std::clamp(p, 0.0, 100.0) / 100.0);
  }
  // The bucket holding the sample of rank `rank` (1-based) in a snapshot; kBuckets when there are fewer.
  uint32_t bucket_at_rank(uint64_t rank) const {
    uint64_t seen = 0;
    for (uint32_t i = 0; i < kBuckets; ++i) {
      seen += buckets_[i].load(std::memory_order_relaxed);
      if (seen >= rank) return i;
    }
    return kBuckets;
  }
  // Samples in buckets above the one holding `value` (bucket resolution).
  uint64_t count_above(uint64_t value) const {
    uint64_t n = 0;
    for (uint32_t i = bucket_of(value / Unit) + 1; i < kBuckets; ++i) n += buckets_[i].load(std::memory_order_relaxed);
    return n;
  }

  // Bucket of a value in units; and the largest value in units a bucket holds.
  static constexpr uint32_t bucket_of(uint64_t units) {
    if (units < kSubBuckets) return static_cast<uint32_t>(units);                 // exact
    const uint32_t octave = 63u - static_cast<uint32_t>(__builtin_clzll(units));  // >= SubBucketBits
    if (octave >= kOctaves) return kBuckets - 1;
    const uint32_t sub = static_cast<uint32_t>(units >> (octave - SubBucketBits)) & (kSubBuckets - 1);
    return kSubBuckets + (octave - SubBucketBits) * kSubBuckets + sub;
  }
  static constexpr uint64_t bucket_upper(uint32_t bucket) {
    if (bucket < kSubBuckets) return bucket;
    const uint32_t octave = SubBucketBits + (bucket - kSubBuckets) / kSubBuckets;
    const uint64_t sub = (bucket - kSubBuckets) % kSubBuckets;
    return ((kSubBuckets + sub + 1) << (octave - SubBucketBits)) - 1;
  }

 private:
  double rank_value(double fraction) const {
    uint64_t total = 0;
    std::array<uint64_t, kBuckets> snapshot{};
    for (uint32_t i = 0; i < kBuckets; ++i) total += snapshot[i] = buckets_[i].load(std::memory_order_relaxed);
    if (total == 0) return 0.0;
    const uint64_t rank =
        std::max<uint64_t>(1, static_cast<uint64_t>(std::ceil(fraction * static_cast<double>(total))));
    uint64_t seen = 0;
    for (uint32_t i = 0; i < kBuckets; ++i) {
      seen += snapshot[i];
      if (seen >= rank) return static_cast<double>(std::min((bucket_upper(i) + 1) * Unit - 1, max()));
    }
    return static_cast<double>(max());
  }

  std::array<std::atomic<uint64_t>, kBuckets> buckets_{};
  std::atomic<uint64_t> count_{0};
  std::atomic<uint64_t> sum_{0};
  std::atomic<uint64_t> max_{0};
};

}  // namespace texstream
