#include "texstream/server/storage/rate_limited_storage.hpp"

#include <algorithm>
#include <chrono>
#include <thread>

namespace texstream::server {

namespace {

uint64_t now_ns() {
  return static_cast<uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
          .count());
}

class LimitedFile final : public StorageFile {
 public:
  LimitedFile(std::unique_ptr<StorageFile> inner, TokenBucket& bucket, std::atomic<uint64_t>* wait_us)
      : inner_(std::move(inner)), bucket_(bucket), wait_us_(wait_us) {}
  Result<uint64_t> read_at(std::span<std::byte> out, uint64_t offset) override {
    const uint64_t wait = bucket_.take(out.size(), now_ns());
    if (wait > 0) {
      std::this_thread::sleep_for(std::chrono::nanoseconds(wait));
      if (wait_us_) wait_us_->fetch_add(wait / 1000, std::memory_order_relaxed);
    }
    return inner_->read_at(out, offset);
  }
  Result<uint64_t> size() override { return inner_->size(); }

 private:
  std::unique_ptr<StorageFile> inner_;
  TokenBucket& bucket_;
  std::atomic<uint64_t>* wait_us_;
};

}  // namespace

// Burst: 50 ms of the rate, at least 1 MiB (one largest mip of a default staging slot), so a limit smooths the
// average without turning every single read into a sleep.
RateLimitedStorage::RateLimitedStorage(Storage& inner, double megabytes_per_s, std::atomic<uint64_t>* wait_us)
    : inner_(inner),
      bucket_(megabytes_per_s * 1e6, std::max(megabytes_per_s * 1e6 * 0.05, double(1 << 20))),
      wait_us_(wait_us) {}

Result<std::unique_ptr<StorageFile>> RateLimitedStorage::open(const std::filesystem::path& path) {
  Result<std::unique_ptr<StorageFile>> f = inner_.open(path);
  if (!f.ok()) return f.error();
  return std::unique_ptr<StorageFile>(new LimitedFile(std::move(f).value(), bucket_, wait_us_));
}

}  // namespace texstream::server
