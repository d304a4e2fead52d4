#pragma once
// Slow-storage emulation (issue 4): wraps any Storage and makes its reads behave like a far or slow origin —
// a spinning disk, a network share, a web server across a WAN — for tests and benchmarks.
//
// Per read: latency + uniform jitter in [0, jitter), with probability `stall_probability` an extra stall of
// `stall_ms`, with probability `failure_rate` a kIo failure (after the delay), and a bandwidth cap shared by
// all reads (a token bucket: the link is one pipe). The random draws are a pure function of (seed, path,
// offset, length, how many times this range was read before), so a run with the same seed and the same reads
// sees the same delays and failures whatever the thread interleaving, and a retry of a failed read draws anew.
// Files are remote(): the server fetches through them on its remote-fetch workers. Thread-safe.
#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>

#include "texstream/server/storage/storage.hpp"
#include "texstream/server/storage/token_bucket.hpp"

namespace texstream::server {

struct SlowStorageParams {
  double latency_ms = 0;
  double jitter_ms = 0;
  double bandwidth_mb_s = 0;  // 0: unlimited
  double stall_probability = 0;
  double stall_ms = 0;
  double failure_rate = 0;
  uint64_t seed = 1;
};

// What one read will suffer. Pure (no clock): unit tests check determinism and the distributions.
struct SlowReadPlan {
  double delay_ms = 0;  // latency + jitter + stall (the bandwidth wait comes on top, from the shared bucket)
  bool stalled = false;
  bool fails = false;
};
SlowReadPlan plan_slow_read(const SlowStorageParams& params, std::string_view path, uint64_t offset, uint64_t length,
                            uint64_t attempt);
// Errors: kInvalidArgument naming the storage.slow_* key that is out of range.
Status validate(const SlowStorageParams& params);

class SlowStorage final : public Storage {
 public:
  SlowStorage(Storage& inner, const SlowStorageParams& params);
  Result<std::unique_ptr<StorageFile>> open(const std::filesystem::path& path) override;
  void cancel_all() override {
    cancelled_.store(true, std::memory_order_relaxed);
    inner_.cancel_all();
  }
  void resume() override {
    cancelled_.store(false, std::memory_order_relaxed);
    inner_.resume();
  }

  // The plan for the next read of this range (counts it as an attempt). Used by the files.
  SlowReadPlan next_plan(const std::string& path, uint64_t offset, uint64_t length);
  // Waits the bandwidth cap's share for `bytes` (no-op when unlimited).
  void take_bandwidth(uint64_t bytes);
  // Sleeps `ns`, in slices, ending early after cancel_all(). False when cancelled.
  bool wait(uint64_t ns);

 private:
  Storage& inner_;
  const SlowStorageParams params_;
  TokenBucket bucket_;
  std::atomic<bool> cancelled_{false};
  std::mutex mutex_;
  std::unordered_map<std::string, uint64_t> attempts_;  // "path@offset+length" → reads so far
};

}  // namespace texstream::server
