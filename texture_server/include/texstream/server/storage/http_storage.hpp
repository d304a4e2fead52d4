#pragma once
// An http:// or https:// origin read with HTTP range requests (libcurl). A file's path is mapped to a URL by
// taking it relative to `root` (the scene folder the server was given) and appending that to the base URL,
// so <scene>/textures/000/00000001.dds is <base>/textures/000/00000001.dds.
//
// - One libcurl handle per thread (each worker keeps its own): connections are kept alive and reused from
//   one range request to the next; no handle is shared between threads.
// - open() does no I/O: a texture whose ranges sit in the disk cache never touches the network, and a dead
//   origin does not stop cached textures from being served. A missing object shows up as kNotFound on read.
// - Every read checks the status code (206 only; 404/410 → kNotFound; 416 → the object ends before offset),
//   the Content-Range against the asked range, and the body length (truncation).
// - Timeouts: connect, whole request, and a low-speed limit (a "slowloris" origin that trickles bytes).
// - Transient failures (connect errors, timeouts, 5xx, truncated bodies) are retried `retries` times with
//   exponential back-off; errors name the URL. kTimeout when the last attempt timed out.
// Thread-safe.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include "texstream/server/storage/storage.hpp"

namespace texstream::server {

struct HttpOptions {
  int64_t connect_timeout_ms = 2000;
  int64_t request_timeout_ms = 10000;
  int64_t low_speed_bytes_s = 1024;
  int64_t low_speed_time_s = 3;
  int64_t retries = 2;
  int64_t retry_backoff_ms = 50;
};

struct HttpCounters {
  std::atomic<uint64_t> requests{0};
  std::atomic<uint64_t> retries{0};
  std::atomic<uint64_t> failures{0};
  std::atomic<uint64_t> bytes{0};
};

class HttpStorage final : public Storage {
 public:
  // `base_url` starts with http:// or https:// (else kInvalidArgument).
  static Result<std::unique_ptr<HttpStorage>> create(std::string base_url, std::filesystem::path root,
                                                     const HttpOptions& options);
  Result<std::unique_ptr<StorageFile>> open(const std::filesystem::path& path) override;
  void cancel_all() override { abort_all(); }
  void resume() override { aborted_.store(false, std::memory_order_relaxed); }

  // The URL for a relative path under the base ("textures.bin").
  std::string url_of(const std::string& relative) const;
  // Fetches a whole (small) object, e.g. the scene's texture table. Same checks, timeouts and retries.
  Result<std::string> fetch_all(const std::string& relative);
  // Makes transfers in progress and back-off waits end soon with kIo (shutdown).
  void abort_all() { aborted_.store(true, std::memory_order_relaxed); }
  const HttpCounters& counters() const { return counters_; }

  // One range read of `url` with retries (the files this storage opens use it). `total`, when given, gets the
  // object's complete length if the origin told it.
  Result<uint64_t> read_range(const std::string& url, std::span<std::byte> out, uint64_t offset,
                              std::optional<uint64_t>* total = nullptr);
  Result<uint64_t> object_size(const std::string& url);

 private:
  HttpStorage(std::string base, std::filesystem::path root, const HttpOptions& options)
      : base_(std::move(base)), root_(std::move(root)), options_(options) {}

  std::string base_;
  std::filesystem::path root_;
  HttpOptions options_;
  std::atomic<bool> aborted_{false};
  HttpCounters counters_;
};

}  // namespace texstream::server
