#pragma once
// The decode helpers of this process (decode_helper.hpp): started lazily on the first decode (a scene of the
// generator's own DDS files never starts one), one per concurrent decode (so at most one per worker), kept
// while idle, replaced after a failure. Thread-safe.
//
// Quarantine (issue 9): a file on which helpers crashed, hung or broke the protocol kQuarantineAfterFailures
// times is refused from then on, for the pool's life, without a helper: a hostile file would otherwise cost
// a process spawn per request forever, and a hang the full timeout of a worker each time. Errors a helper
// reports itself (a corrupt file it rejects) are the file's ordinary kCorrupt and never quarantine it.
#include <chrono>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"
#include "texstream/server/decode/decode_helper.hpp"
#include "texstream/server/storage/storage.hpp"

namespace texstream::server {

struct DecodeHelperPoolStats {
  uint64_t helpers_started = 0;
  uint64_t helper_failures = 0;  // decodes that ended with the helper crashed, hung or out of protocol
  uint64_t files_quarantined = 0;
  uint64_t quarantine_refusals = 0;  // decodes refused at once because their file is quarantined
};

class DecodeHelperPool {
 public:
  // Default per-message wait for a helper: a decode of one slot-sized (≤ 1 MiB RGBA8) mip takes milliseconds;
  // ten seconds only ever ends a helper stuck on a hostile file.
  static constexpr std::chrono::milliseconds kDefaultTimeout{10'000};
  // Helper failures on one file before it is quarantined (issue 9: "a file that crashed it twice"). One is
  // forgiven: a helper killed from outside mid-decode (an OOM kill, an operator) is not the file's fault.
  static constexpr uint32_t kQuarantineAfterFailures = 2;

  // `exe`: the texstream-decode executable (find_decode_helper()).
  explicit DecodeHelperPool(std::filesystem::path exe, std::chrono::milliseconds timeout = kDefaultTimeout);

  // DecodeHelper::decode() on an idle helper or a new one. Errors name `path`; a helper that cannot be
  // started is kIo; a quarantined `path` is kCorrupt at once, saying so.
  Status decode(StorageFile& file, const std::filesystem::path& path, uint32_t level, Extent2D expected,
                std::span<std::byte> out, uint64_t& bytes_read);

  uint64_t helpers_started() const;
  bool quarantined(const std::filesystem::path& path) const;
  DecodeHelperPoolStats stats() const;

 private:
  struct FileFailures {
    uint32_t count = 0;
    std::string last;  // the last failure's message (how the helper ended)
  };
  // Counts a helper failure on `path` (mutex_ held); true if that quarantined it.
  bool note_failure(const std::string& key, std::string message);

  std::filesystem::path exe_;
  std::chrono::milliseconds timeout_;
  mutable std::mutex mutex_;
  std::vector<std::unique_ptr<DecodeHelper>> idle_;
  // Keyed by the path as the texture table names it: one entry per file a helper ever failed on, so bounded
  // by the scene's files.
  std::unordered_map<std::string, FileFailures> failures_;
  DecodeHelperPoolStats stats_;
};

// Where texstream-decode is: $TEXSTREAM_DECODE_HELPER if set; else next to this process's executable; else
// where the build put it (tests and benchmarks run from other folders). Errors: kNotFound listing the places.
Result<std::filesystem::path> find_decode_helper();

// The pool decode_mip_rgba8() uses (created on first use).
DecodeHelperPool& default_decode_helper_pool();
// Its statistics, or nothing if no decode created it yet (reading them never creates it).
std::optional<DecodeHelperPoolStats> default_decode_helper_pool_stats();

}  // namespace texstream::server
