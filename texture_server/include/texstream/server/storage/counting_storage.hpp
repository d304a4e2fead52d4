#pragma once
// A Storage that counts what the tier above asks of the one below it: reads and bytes. For read-amplification
// figures (texstream-bench pages' page_read_amp) and tests that prove a reader makes exactly the reads it should.
// Thread-safe (relaxed counters: statistics).
#include <atomic>
#include <cstdint>
#include <memory>

#include "texstream/server/storage/storage.hpp"

namespace texstream::server {

class CountingStorage final : public Storage {
 public:
  explicit CountingStorage(Storage& inner) : inner_(inner) {}
  Result<std::unique_ptr<StorageFile>> open(const std::filesystem::path& path) override;
  void cancel_all() override { inner_.cancel_all(); }
  void resume() override { inner_.resume(); }

  uint64_t reads() const { return reads_.load(std::memory_order_relaxed); }
  uint64_t bytes() const { return bytes_.load(std::memory_order_relaxed); }

 private:
  class File;
  Storage& inner_;
  std::atomic<uint64_t> reads_{0}, bytes_{0};
};

}  // namespace texstream::server
