#pragma once
// Storage that caps the read rate of another Storage with a TokenBucket (server.rate_limit_mb_s). Only
// storage reads pass through it: RAM-cache hits never touch storage, so they are never limited. The wait is a
// sleep in the reading worker thread, never in the dispatcher (which keeps serving hits meanwhile).
// Thread-safe.
#include <cstdint>
#include <memory>

#include "texstream/server/server_stats.hpp"
#include "texstream/server/storage.hpp"
#include "texstream/server/token_bucket.hpp"

namespace texstream::server {

class RateLimitedStorage final : public Storage {
 public:
  // `stats` (may be null) receives the time spent waiting.
  RateLimitedStorage(Storage& inner, double megabytes_per_s, ServerStats* stats);
  Result<std::unique_ptr<StorageFile>> open(const std::filesystem::path& path) override;
  void cancel_all() override { inner_.cancel_all(); }
  void resume() override { inner_.resume(); }

 private:
  Storage& inner_;
  TokenBucket bucket_;
  ServerStats* stats_;
};

}  // namespace texstream::server
