#include "texstream/server/decode/decode_helper_pool.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <cstdlib>

namespace texstream::server {

namespace {

// Idle helpers kept beyond this are closed: one per worker is all the server uses (worker_threads ≤ 64, 2 by
// default); more would only hold memory.
constexpr size_t kMaxIdle = 8;

// default_decode_helper_pool() once created: statistics are read without creating it (format_stats).
std::atomic<const DecodeHelperPool*> g_default_pool{nullptr};

}  // namespace

DecodeHelperPool::DecodeHelperPool(std::filesystem::path exe, std::chrono::milliseconds timeout)
    : exe_(std::move(exe)), timeout_(timeout) {}

uint64_t DecodeHelperPool::helpers_started() const {
  std::lock_guard lock(mutex_);
  return stats_.helpers_started;
}

bool DecodeHelperPool::quarantined(const std::filesystem::path& path) const {
  std::lock_guard lock(mutex_);
  const auto it = failures_.find(path.string());
  return it != failures_.end() && it->second.count >= kQuarantineAfterFailures;
}

DecodeHelperPoolStats DecodeHelperPool::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

bool DecodeHelperPool::note_failure(const std::string& key, std::string message) {
  ++stats_.helper_failures;
  FileFailures& f = failures_[key];
  f.last = std::move(message);
  // Two workers may fail on the same file at once: only the failure that reaches the bound quarantines it.
  if (++f.count != kQuarantineAfterFailures) return false;
  ++stats_.files_quarantined;
  return true;
}

Status DecodeHelperPool::decode(StorageFile& file, const std::filesystem::path& path, uint32_t level, Extent2D expected,
                                std::span<std::byte> out, uint64_t& bytes_read) {
  const std::string key = path.string();
  std::unique_ptr<DecodeHelper> helper;
  {
    std::lock_guard lock(mutex_);
    if (const auto it = failures_.find(key); it != failures_.end() && it->second.count >= kQuarantineAfterFailures) {
      ++stats_.quarantine_refusals;
      return make_error(ErrorCode::kCorrupt,
                        fmt::format("'{}': cannot decode mip {}: quarantined after crashing the decode helper {} "
                                    "times (last: {})",
                                    key, level, it->second.count, it->second.last));
    }
    while (!idle_.empty() && !helper) {
      helper = std::move(idle_.back());
      idle_.pop_back();
      if (!helper->usable()) helper.reset();  // died while idle (killed from outside): start another
    }
  }
  if (!helper) {
    Result<std::unique_ptr<DecodeHelper>> spawned = DecodeHelper::spawn(exe_);
    if (!spawned.ok()) {
      return make_error(ErrorCode::kIo,
                        fmt::format("'{}': cannot decode mip {}: {}", key, level, spawned.error().message));
    }
    helper = std::move(spawned).value();
    std::lock_guard lock(mutex_);
    ++stats_.helpers_started;
    spdlog::debug("started decode helper {} (pid {})", exe_.string(), helper->pid());
  }
  Status s = helper->decode(file, path, level, expected, out, bytes_read, timeout_);
  if (helper->helper_failed()) {
    // The message already names the file: the refusals keep what follows "'<path>': cannot decode ".
    std::string how = s.ok() ? std::string("no error") : s.error().message;
    if (const std::string prefix = fmt::format("'{}': cannot decode ", key); how.rfind(prefix, 0) == 0) {
      how.erase(0, prefix.size());
    }
    bool now_quarantined = false;
    {
      std::lock_guard lock(mutex_);
      now_quarantined = note_failure(key, std::move(how));
    }
    if (now_quarantined) {
      spdlog::warn(
          "'{}' quarantined: it crashed or hung the decode helper {} times; its mips are refused "
          "(kCorrupt) without decoding until the server restarts",
          key, kQuarantineAfterFailures);
    }
  } else if (helper->usable()) {
    std::lock_guard lock(mutex_);
    if (idle_.size() < kMaxIdle) idle_.push_back(std::move(helper));
  }
  // A broken helper is already killed and reaped; its object goes here, outside the lock.
  return s;
}

Result<std::filesystem::path> find_decode_helper() {
  if (const char* env = std::getenv("TEXSTREAM_DECODE_HELPER"); env != nullptr && *env != '\0') {
    return std::filesystem::path(env);
  }
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  std::string tried;
  if (!ec) {
    const std::filesystem::path next_to = self.parent_path() / "texstream-decode";
    if (std::filesystem::exists(next_to, ec)) return next_to;
    tried = next_to.string();
  }
#ifdef TEXSTREAM_DECODE_HELPER_BUILD_PATH
  const std::filesystem::path built = TEXSTREAM_DECODE_HELPER_BUILD_PATH;
  if (std::filesystem::exists(built, ec)) return built;
  tried += (tried.empty() ? "" : ", ") + built.string();
#endif
  return make_error(ErrorCode::kNotFound,
                    fmt::format("texstream-decode not found (tried {}; set TEXSTREAM_DECODE_HELPER)", tried));
}

DecodeHelperPool& default_decode_helper_pool() {
  // The path is resolved once: a helper missing at start-up stays an error per decode, never a crash.
  static DecodeHelperPool pool([] {
    Result<std::filesystem::path> exe = find_decode_helper();
    if (!exe.ok()) {
      spdlog::error("{}", exe.error().message);
      return std::filesystem::path("texstream-decode");  // spawn() then fails with kIo naming it
    }
    return std::move(exe).value();
  }());
  [[maybe_unused]] static const bool published = (g_default_pool.store(&pool, std::memory_order_release), true);
  return pool;
}

std::optional<DecodeHelperPoolStats> default_decode_helper_pool_stats() {
  const DecodeHelperPool* pool = g_default_pool.load(std::memory_order_acquire);
  if (pool == nullptr) return std::nullopt;
  return pool->stats();
}

}  // namespace texstream::server
