#include "texstream/server/storage/slow_storage.hpp"

#include <xxhash.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>

namespace texstream::server {

namespace {

// SplitMix64 (Steele, Lea, Flood 2014): one 64-bit mix per draw, enough for emulation noise.
uint64_t splitmix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

// Uniform in [0, 1) from the top 53 bits.
double unit(uint64_t x) { return static_cast<double>(x >> 11) * (1.0 / 9007199254740992.0); }

uint64_t now_ns() {
  return static_cast<uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
          .count());
}

class SlowFile final : public StorageFile {
 public:
  SlowFile(SlowStorage& owner, std::unique_ptr<StorageFile> inner, std::string path)
      : owner_(owner), inner_(std::move(inner)), path_(std::move(path)) {}
  Result<uint64_t> read_at(std::span<std::byte> out, uint64_t offset) override {
    const SlowReadPlan plan = owner_.next_plan(path_, offset, out.size());
    const bool waited = owner_.wait(static_cast<uint64_t>(plan.delay_ms * 1e6));
    if (!waited) return make_error(ErrorCode::kIo, "slow-storage emulation: read of '" + path_ + "' cancelled");
    if (plan.fails) {
      return make_error(ErrorCode::kIo, "slow-storage emulation: injected failure reading " +
                                            std::to_string(out.size()) + " bytes at offset " + std::to_string(offset) +
                                            " of '" + path_ + "' (storage.slow_failure_rate)");
    }
    owner_.take_bandwidth(out.size());
    return inner_->read_at(out, offset);
  }
  Result<uint64_t> size() override { return inner_->size(); }
  bool remote() const override { return true; }

 private:
  SlowStorage& owner_;
  std::unique_ptr<StorageFile> inner_;
  std::string path_;
};

}  // namespace

SlowReadPlan plan_slow_read(const SlowStorageParams& p, std::string_view path, uint64_t offset, uint64_t length,
                            uint64_t attempt) {
  uint64_t h = XXH3_64bits_withSeed(path.data(), path.size(), p.seed);
  h = splitmix64(h ^ offset);
  h = splitmix64(h ^ length);
  h = splitmix64(h ^ attempt);
  const double u_jitter = unit(splitmix64(h + 1));
  const double u_stall = unit(splitmix64(h + 2));
  const double u_fail = unit(splitmix64(h + 3));
  SlowReadPlan plan;
  plan.delay_ms = p.latency_ms + u_jitter * p.jitter_ms;
  plan.stalled = u_stall < p.stall_probability;
  if (plan.stalled) plan.delay_ms += p.stall_ms;
  plan.fails = u_fail < p.failure_rate;
  return plan;
}

Status validate(const SlowStorageParams& p) {
  auto bad = [](const char* key, const char* what) {
    return make_error(ErrorCode::kInvalidArgument, std::string("storage.") + key + " " + what);
  };
  if (!(p.latency_ms >= 0)) return bad("slow_latency_ms", "must be >= 0");
  if (!(p.jitter_ms >= 0)) return bad("slow_jitter_ms", "must be >= 0");
  if (!(p.bandwidth_mb_s >= 0)) return bad("slow_bandwidth_mb_s", "must be >= 0");
  if (!(p.stall_probability >= 0 && p.stall_probability <= 1))
    return bad("slow_stall_probability", "must be in [0, 1]");
  if (!(p.stall_ms >= 0)) return bad("slow_stall_ms", "must be >= 0");
  if (!(p.failure_rate >= 0 && p.failure_rate <= 1)) return bad("slow_failure_rate", "must be in [0, 1]");
  return ok_status();
}

// Burst of one 64 KiB block: a link has no reserve worth speaking of, so a large read waits for its bytes.
SlowStorage::SlowStorage(Storage& inner, const SlowStorageParams& params)
    : inner_(inner),
      params_(params),
      bucket_(params.bandwidth_mb_s > 0 ? params.bandwidth_mb_s * 1e6 : 1.0, 64.0 * 1024) {}

Result<std::unique_ptr<StorageFile>> SlowStorage::open(const std::filesystem::path& path) {
  Result<std::unique_ptr<StorageFile>> f = inner_.open(path);
  if (!f.ok()) return f.error();
  return std::unique_ptr<StorageFile>(new SlowFile(*this, std::move(f).value(), path.string()));
}

SlowReadPlan SlowStorage::next_plan(const std::string& path, uint64_t offset, uint64_t length) {
  uint64_t attempt;
  {
    std::lock_guard lock(mutex_);
    attempt = attempts_[path + "@" + std::to_string(offset) + "+" + std::to_string(length)]++;
  }
  return plan_slow_read(params_, path, offset, length, attempt);
}

void SlowStorage::take_bandwidth(uint64_t bytes) {
  if (!(params_.bandwidth_mb_s > 0)) return;
  wait(bucket_.take(bytes, now_ns()));
}

bool SlowStorage::wait(uint64_t ns) {
  // Slices of 10 ms: cancel_all() (server stopping) ends a long emulated stall soon.
  constexpr uint64_t kSliceNs = 10'000'000;
  const uint64_t end = now_ns() + ns;
  for (uint64_t now = now_ns(); now < end; now = now_ns()) {
    if (cancelled_.load(std::memory_order_relaxed)) return false;
    std::this_thread::sleep_for(std::chrono::nanoseconds(std::min(kSliceNs, end - now)));
  }
  return !cancelled_.load(std::memory_order_relaxed);
}

}  // namespace texstream::server
