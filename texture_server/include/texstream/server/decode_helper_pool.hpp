#pragma once
// The decode helpers of this process (decode_helper.hpp): started lazily on the first decode (a scene of the
// generator's own DDS files never starts one), one per concurrent decode (so at most one per worker), kept
// while idle, replaced after a failure. Thread-safe.
#include <chrono>
#include <filesystem>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/protocol/texel_format.hpp"
#include "texstream/server/decode_helper.hpp"
#include "texstream/server/storage.hpp"

namespace texstream::server {

class DecodeHelperPool {
 public:
  // Default per-message wait for a helper: a decode of one slot-sized (≤ 1 MiB RGBA8) mip takes milliseconds;
  // ten seconds only ever ends a helper stuck on a hostile file.
  static constexpr std::chrono::milliseconds kDefaultTimeout{10'000};

  // `exe`: the texstream-decode executable (find_decode_helper()).
  explicit DecodeHelperPool(std::filesystem::path exe, std::chrono::milliseconds timeout = kDefaultTimeout);

  // DecodeHelper::decode() on an idle helper or a new one. Errors name `path`; a helper that cannot be
  // started is kIo.
  Status decode(StorageFile& file, const std::filesystem::path& path, uint32_t level, Extent2D expected,
                std::span<std::byte> out, uint64_t& bytes_read);

  uint64_t helpers_started() const;

 private:
  std::filesystem::path exe_;
  std::chrono::milliseconds timeout_;
  mutable std::mutex mutex_;
  std::vector<std::unique_ptr<DecodeHelper>> idle_;
  uint64_t started_ = 0;
};

// Where texstream-decode is: $TEXSTREAM_DECODE_HELPER if set; else next to this process's executable; else
// where the build put it (tests and benchmarks run from other folders). Errors: kNotFound listing the places.
Result<std::filesystem::path> find_decode_helper();

// The pool decode_mip_rgba8() uses (created on first use).
DecodeHelperPool& default_decode_helper_pool();

}  // namespace texstream::server
