#pragma once
// A Storage in front of a remote or slow one that keeps every range it reads in a DiskCache (seed 002 §3.2's
// local disk cache tier). A read whose exact range is cached is served from disk (checksum verified) and never
// touches the origin — also when the origin is down; any other read goes to the origin and its bytes are
// stored. local() tells the server which reads can be served now without a remote fetch.
// Counts bytes by tier for the benchmark's disk-cache reuse figure. Thread-safe.
#include <atomic>
#include <cstdint>
#include <filesystem>

#include "texstream/server/storage/disk_cache.hpp"
#include "texstream/server/storage/storage.hpp"

namespace texstream::server {

struct TierCounters {
  std::atomic<uint64_t> bytes_from_disk_cache{0};
  std::atomic<uint64_t> bytes_from_origin{0};
};

class CachingStorage final : public Storage {
 public:
  // Keys are paths relative to `root` (the scene folder), so the cache is valid for the same origin content
  // whatever local folder name the server was started with.
  CachingStorage(Storage& origin, DiskCache& cache, std::filesystem::path root);
  Result<std::unique_ptr<StorageFile>> open(const std::filesystem::path& path) override;
  void cancel_all() override { origin_.cancel_all(); }
  void resume() override { origin_.resume(); }

  const TierCounters& counters() const { return counters_; }
  DiskCache& cache() { return cache_; }

 private:
  Storage& origin_;
  DiskCache& cache_;
  std::filesystem::path root_;
  TierCounters counters_;
};

}  // namespace texstream::server
