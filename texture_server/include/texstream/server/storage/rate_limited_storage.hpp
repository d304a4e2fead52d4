#pragma once
// Storage that caps the read rate of another Storage with a TokenBucket (server.rate_limit_mb_s). Only
// storage reads pass through it: RAM-cache hits never touch storage, so they are never limited. The wait is a
// sleep in the reading worker thread, never in the dispatcher (which keeps serving hits meanwhile).
// Thread-safe.
#include <atomic>
#include <cstdint>
#include <memory>

#include "texstream/server/storage/storage.hpp"
#include "texstream/server/storage/token_bucket.hpp"

namespace texstream::server {

class RateLimitedStorage final : public Storage {
 public:
  // `wait_us` (may be null) counts the microseconds spent waiting (ServerStats::rate_limit_wait_us; a
  // counter, not the statistics, so storage stays below the loader).
  RateLimitedStorage(Storage& inner, double megabytes_per_s, std::atomic<uint64_t>* wait_us);
  Result<std::unique_ptr<StorageFile>> open(const std::filesystem::path& path) override;
  void cancel_all() override { inner_.cancel_all(); }
  void resume() override { inner_.resume(); }

 private:
  Storage& inner_;
  TokenBucket bucket_;
  std::atomic<uint64_t>* wait_us_;
};

}  // namespace texstream::server
