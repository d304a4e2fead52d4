#include "texstream/server/storage/http_storage.hpp"

#include <curl/curl.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <mutex>
#include <thread>

#include "texstream/server/storage/content_range.hpp"
#include "texstream/server/storage/relative_path.hpp"

namespace texstream::server {

namespace {

// fetch_all() is for small objects (the texture table: 16 bytes + 32 per texture); this bounds what a broken
// origin can make us hold in memory.
constexpr size_t kMaxWholeObjectBytes = 256u << 20;
// Back-off waits are cut into pieces this long so that abort_all() ends them soon.
constexpr std::chrono::milliseconds kBackoffSlice{10};

void global_init() {
  static std::once_flag once;
  std::call_once(once, [] { curl_global_init(CURL_GLOBAL_DEFAULT); });
}

// One easy handle per thread: curl_easy_reset keeps its connection cache, so a worker's next range request
// reuses the kept-alive connection to the origin (no new TCP/TLS handshake per mip).
struct ThreadHandle {
  CURL* handle = nullptr;
  ~ThreadHandle() {
    if (handle) curl_easy_cleanup(handle);
  }
};

CURL* thread_handle() {
  thread_local ThreadHandle t;
  if (!t.handle) {
    t.handle = curl_easy_init();
  } else {
    curl_easy_reset(t.handle);
  }
  return t.handle;
}

struct Transfer {
  std::span<std::byte> out;      // range read: the caller's buffer
  std::string* whole = nullptr;  // fetch_all: grows
  uint64_t received = 0;
  bool overflow = false;      // the origin sent more than fits
  std::string content_range;  // of the last response (a 100 Continue is followed by the real one)
  const std::atomic<bool>* aborted = nullptr;
};

size_t on_body(char* data, size_t size, size_t count, void* user) {
  Transfer& t = *static_cast<Transfer*>(user);
  const size_t n = size * count;
  if (t.whole) {
    if (t.whole->size() + n > kMaxWholeObjectBytes) {
      t.overflow = true;
      return 0;  // aborts the transfer (CURLE_WRITE_ERROR)
    }
    t.whole->append(data, n);
    t.received += n;
    return n;
  }
  if (t.received + n > t.out.size()) {
    t.overflow = true;
    return 0;
  }
  std::memcpy(t.out.data() + t.received, data, n);
  t.received += n;
  return n;
}

size_t on_header(char* data, size_t size, size_t count, void* user) {
  Transfer& t = *static_cast<Transfer*>(user);
  const size_t n = size * count;
  std::string_view line(data, n);
  if (line.substr(0, 5) == "HTTP/") t.content_range.clear();
  constexpr std::string_view kName = "content-range:";
  if (line.size() > kName.size()) {
    std::string lower(line.substr(0, kName.size()));
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
    if (lower == kName) t.content_range = std::string(line.substr(kName.size()));
  }
  return n;
}

int on_progress(void* user, curl_off_t, curl_off_t, curl_off_t, curl_off_t) {
  const Transfer& t = *static_cast<const Transfer*>(user);
  return t.aborted->load(std::memory_order_relaxed) ? 1 : 0;  // non-zero aborts (CURLE_ABORTED_BY_CALLBACK)
}

struct Attempt {
  Result<uint64_t> result;
  bool transient;  // worth another try
};

Attempt fail(ErrorCode code, std::string message, bool transient) {
  return Attempt{Error{code, std::move(message)}, transient};
}

}  // namespace

Result<std::unique_ptr<HttpStorage>> HttpStorage::create(std::string base_url, std::filesystem::path root,
                                                         const HttpOptions& options) {
  if (base_url.rfind("http://", 0) != 0 && base_url.rfind("https://", 0) != 0) {
    return make_error(ErrorCode::kInvalidArgument,
                      "storage.origin '" + base_url + "': an http origin must start with http:// or https://");
  }
  while (!base_url.empty() && base_url.back() == '/') base_url.pop_back();
  global_init();
  return std::unique_ptr<HttpStorage>(new HttpStorage(std::move(base_url), std::move(root), options));
}

namespace {

class HttpFile final : public StorageFile {
 public:
  HttpFile(HttpStorage& storage, std::string url) : storage_(storage), url_(std::move(url)) {}
  Result<uint64_t> read_at(std::span<std::byte> out, uint64_t offset) override {
    return storage_.read_range(url_, out, offset);
  }
  Result<uint64_t> size() override {
    if (!size_) {
      Result<uint64_t> s = storage_.object_size(url_);
      if (!s.ok()) return s;
      size_ = *s;
    }
    return *size_;
  }
  bool remote() const override { return true; }

 private:
  HttpStorage& storage_;
  std::string url_;
  std::optional<uint64_t> size_;
};

}  // namespace

std::string HttpStorage::url_of(const std::string& relative) const {
  std::string url;
  url.reserve(base_.size() + 1 + relative.size());
  url.append(base_).push_back('/');
  url.append(relative);
  return url;
}

Result<std::unique_ptr<StorageFile>> HttpStorage::open(const std::filesystem::path& path) {
  Result<std::string> rel = relative_under(path, root_);
  if (!rel.ok()) return rel.error();
  return std::unique_ptr<StorageFile>(new HttpFile(*this, url_of(*rel)));
}

namespace {

// One request. `out` empty and `whole` set: a plain GET of the whole object; else bytes [offset, offset+len).
Attempt attempt(const std::string& url, std::span<std::byte> out, std::string* whole, uint64_t offset,
                const HttpOptions& o, const std::atomic<bool>& aborted, std::optional<uint64_t>* total) {
  CURL* h = thread_handle();
  if (!h) return fail(ErrorCode::kIo, "'" + url + "': curl_easy_init failed", false);
  Transfer t;
  t.out = out;
  t.whole = whole;
  t.aborted = &aborted;
  char errbuf[CURL_ERROR_SIZE] = {0};
  std::string range;
  curl_easy_setopt(h, CURLOPT_URL, url.c_str());
  curl_easy_setopt(h, CURLOPT_PROTOCOLS_STR, "http,https");
  curl_easy_setopt(h, CURLOPT_NOSIGNAL, 1L);  // worker threads: no SIGALRM for timeouts
  curl_easy_setopt(h, CURLOPT_FOLLOWLOCATION, 0L);
  curl_easy_setopt(h, CURLOPT_TCP_KEEPALIVE, 1L);
  curl_easy_setopt(h, CURLOPT_CONNECTTIMEOUT_MS, static_cast<long>(o.connect_timeout_ms));
  curl_easy_setopt(h, CURLOPT_TIMEOUT_MS, static_cast<long>(o.request_timeout_ms));
  if (o.low_speed_bytes_s > 0) {
    curl_easy_setopt(h, CURLOPT_LOW_SPEED_LIMIT, static_cast<long>(o.low_speed_bytes_s));
    curl_easy_setopt(h, CURLOPT_LOW_SPEED_TIME, static_cast<long>(o.low_speed_time_s));
  }
  if (!whole) {
    range = std::to_string(offset) + "-" + std::to_string(offset + out.size() - 1);
    curl_easy_setopt(h, CURLOPT_RANGE, range.c_str());
  }
  curl_easy_setopt(h, CURLOPT_WRITEFUNCTION, on_body);
  curl_easy_setopt(h, CURLOPT_WRITEDATA, &t);
  curl_easy_setopt(h, CURLOPT_HEADERFUNCTION, on_header);
  curl_easy_setopt(h, CURLOPT_HEADERDATA, &t);
  curl_easy_setopt(h, CURLOPT_NOPROGRESS, 0L);
  curl_easy_setopt(h, CURLOPT_XFERINFOFUNCTION, on_progress);
  curl_easy_setopt(h, CURLOPT_XFERINFODATA, &t);
  curl_easy_setopt(h, CURLOPT_ERRORBUFFER, errbuf);
  const CURLcode rc = curl_easy_perform(h);
  long status = 0;
  curl_easy_getinfo(h, CURLINFO_RESPONSE_CODE, &status);
  const std::string what = "'" + url + "'" + (whole ? "" : " bytes " + range);

  if (aborted.load(std::memory_order_relaxed)) return fail(ErrorCode::kIo, what + ": aborted (server stopping)", false);
  if (rc == CURLE_OPERATION_TIMEDOUT) {
    return fail(ErrorCode::kTimeout,
                what + ": timed out (" + (errbuf[0] ? std::string(errbuf) : curl_easy_strerror(rc)) +
                    "; storage.request_timeout_ms=" + std::to_string(o.request_timeout_ms) +
                    ", low_speed_bytes_s=" + std::to_string(o.low_speed_bytes_s) + ")",
                true);
  }
  if (rc == CURLE_PARTIAL_FILE) {
    return fail(ErrorCode::kIo,
                what + ": truncated body (" + std::to_string(t.received) +
                    " bytes arrived: " + (errbuf[0] ? std::string(errbuf) : curl_easy_strerror(rc)) + ")",
                true);
  }
  if (rc != CURLE_OK && !(rc == CURLE_WRITE_ERROR && t.overflow)) {
    // No status line at all (connection refused, reset, nothing received): the origin is down, or cannot be
    // reached. kUnavailable: not this object's fault (the renderer asks again in a later cycle, uncounted).
    if (status == 0) {
      return fail(ErrorCode::kUnavailable, what + ": " + (errbuf[0] ? std::string(errbuf) : curl_easy_strerror(rc)),
                  true);
    }
    if (rc != CURLE_WRITE_ERROR) {
      return fail(ErrorCode::kIo, what + ": " + (errbuf[0] ? std::string(errbuf) : curl_easy_strerror(rc)), true);
    }
  }
  if (status == 404 || status == 410)
    return fail(ErrorCode::kNotFound, what + ": HTTP " + std::to_string(status), false);
  // A gateway or proxy with nothing behind it, or an origin that says it is overloaded or restarting.
  if (status == 502 || status == 503 || status == 504) {
    return fail(ErrorCode::kUnavailable, what + ": HTTP " + std::to_string(status), true);
  }
  if (status >= 500) return fail(ErrorCode::kIo, what + ": HTTP " + std::to_string(status), true);
  if (whole) {
    if (status != 200)
      return fail(ErrorCode::kIo, what + ": HTTP " + std::to_string(status) + " (expected 200)", false);
    if (t.overflow)
      return fail(ErrorCode::kCorrupt, what + ": larger than " + std::to_string(kMaxWholeObjectBytes) + " bytes",
                  false);
    return Attempt{t.received, false};
  }
  if (status == 416) {
    // Range not satisfiable: the object ends before `offset` (read_at's contract: 0 bytes), if the origin
    // says so with its complete length.
    Result<ContentRange> cr = parse_content_range(t.content_range);
    if (cr.ok() && cr->total && offset >= *cr->total) return Attempt{uint64_t{0}, false};
    return fail(ErrorCode::kCorrupt, what + ": HTTP 416 without a complete length at or below the offset", false);
  }
  if (status == 200) {
    return fail(ErrorCode::kUnsupported,
                what + ": the origin ignored the Range header (HTTP 200); range requests are required", false);
  }
  if (status != 206) return fail(ErrorCode::kIo, what + ": unexpected HTTP " + std::to_string(status), false);
  if (t.content_range.empty()) return fail(ErrorCode::kCorrupt, what + ": HTTP 206 without Content-Range", false);
  Result<ContentRange> cr = parse_content_range(t.content_range);
  if (!cr.ok()) return fail(ErrorCode::kCorrupt, what + ": " + cr.error().message, false);
  if (total) *total = cr->total;
  Result<uint64_t> expected = check_range_answer(*cr, offset, out.size(), url);
  if (!expected.ok()) return Attempt{expected.error(), false};
  if (t.overflow) return fail(ErrorCode::kCorrupt, what + ": the body is longer than its Content-Range", false);
  if (t.received != *expected) {
    return fail(
        ErrorCode::kIo,
        what + ": truncated body (" + std::to_string(t.received) + " of " + std::to_string(*expected) + " bytes)",
        true);
  }
  return Attempt{t.received, false};
}

}  // namespace

Result<uint64_t> HttpStorage::read_range(const std::string& url, std::span<std::byte> out, uint64_t offset,
                                         std::optional<uint64_t>* total) {
  if (out.empty()) return uint64_t{0};
  Attempt a{uint64_t{0}, false};
  for (int64_t i = 0; i <= options_.retries; ++i) {
    if (i > 0) {
      counters_.retries.fetch_add(1, std::memory_order_relaxed);
      // Exponential back-off: a restarting or overloaded origin gets room instead of a burst of retries.
      const auto wait = std::chrono::milliseconds(options_.retry_backoff_ms << std::min<int64_t>(i - 1, 16));
      const auto end = std::chrono::steady_clock::now() + wait;
      while (std::chrono::steady_clock::now() < end && !aborted_.load(std::memory_order_relaxed)) {
        std::this_thread::sleep_for(
            std::min<std::chrono::steady_clock::duration>(kBackoffSlice, end - std::chrono::steady_clock::now()));
      }
    }
    counters_.requests.fetch_add(1, std::memory_order_relaxed);
    a = attempt(url, out, nullptr, offset, options_, aborted_, total);
    if (a.result.ok() || !a.transient || aborted_.load(std::memory_order_relaxed)) break;
    spdlog::debug("http origin: {} (attempt {} of {})", a.result.error().message, i + 1, options_.retries + 1);
  }
  if (!a.result.ok()) {
    counters_.failures.fetch_add(1, std::memory_order_relaxed);
    return a.result.error();
  }
  counters_.bytes.fetch_add(*a.result, std::memory_order_relaxed);
  return a.result;
}

Result<uint64_t> HttpStorage::object_size(const std::string& url) {
  // A one-byte range: the 206's Content-Range carries the complete length.
  std::byte one[1];
  std::optional<uint64_t> total;
  Result<uint64_t> got = read_range(url, one, 0, &total);
  if (!got.ok()) return got;
  if (*got == 0) return uint64_t{0};  // 416 at offset 0: an empty object
  if (!total) return make_error(ErrorCode::kUnsupported, "'" + url + "': the origin does not tell the object's length");
  return *total;
}

Result<std::string> HttpStorage::fetch_all(const std::string& relative) {
  const std::string url = url_of(relative);
  Attempt a{uint64_t{0}, false};
  std::string body;
  for (int64_t i = 0; i <= options_.retries; ++i) {
    if (i > 0)
      std::this_thread::sleep_for(std::chrono::milliseconds(options_.retry_backoff_ms << std::min<int64_t>(i - 1, 16)));
    body.clear();
    counters_.requests.fetch_add(1, std::memory_order_relaxed);
    a = attempt(url, {}, &body, 0, options_, aborted_, nullptr);
    if (a.result.ok() || !a.transient) break;
  }
  if (!a.result.ok()) return a.result.error();
  return body;
}

}  // namespace texstream::server
