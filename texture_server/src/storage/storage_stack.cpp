#include "texstream/server/storage/storage_stack.hpp"

#include <unistd.h>

#include <fstream>

#include "texstream/server/storage/posix_storage.hpp"

namespace texstream::server {

namespace fs = std::filesystem;

namespace {

constexpr const char* kTextureTable = "textures.bin";  // scene_format.hpp's layout

bool is_url(const std::string& s) { return s.rfind("http://", 0) == 0 || s.rfind("https://", 0) == 0; }

}  // namespace

HttpOptions http_options(const StorageConfig& c) {
  HttpOptions o;
  o.connect_timeout_ms = c.connect_timeout_ms;
  o.request_timeout_ms = c.request_timeout_ms;
  o.low_speed_bytes_s = c.low_speed_bytes_s;
  o.low_speed_time_s = c.low_speed_time_s;
  o.retries = c.retries;
  o.retry_backoff_ms = c.retry_backoff_ms;
  return o;
}

SlowStorageParams slow_params(const StorageConfig& c) {
  SlowStorageParams p;
  p.latency_ms = c.slow_latency_ms;
  p.jitter_ms = c.slow_jitter_ms;
  p.bandwidth_mb_s = c.slow_bandwidth_mb_s;
  p.stall_probability = c.slow_stall_probability;
  p.stall_ms = c.slow_stall_ms;
  p.failure_rate = c.slow_failure_rate;
  p.seed = static_cast<uint64_t>(c.slow_seed);
  return p;
}

StorageStack::~StorageStack() {
  if (http) http->abort_all();
  caching.reset();
  disk_cache.reset();
  slow.reset();
  http.reset();
  local.reset();
}

std::string StorageStack::describe() const {
  std::string s = http ? "http origin" : "local origin '" + scene_dir.string() + "'";
  if (slow) s += " + slow-storage emulation";
  if (disk_cache) s += " + disk cache '" + disk_cache->dir().string() + "'";
  return s;
}

Result<std::unique_ptr<StorageStack>> make_storage_stack(const StorageConfig& c, const fs::path& scene_dir) {
  auto stack = std::make_unique<StorageStack>();
  Storage* origin = nullptr;
  if (is_url(c.origin)) {
    Result<std::unique_ptr<HttpStorage>> http = HttpStorage::create(c.origin, scene_dir, http_options(c));
    if (!http.ok()) return http.error();
    stack->http = std::move(http).value();
    stack->scene_dir = scene_dir;
    if (!fs::exists(scene_dir / kTextureTable)) {
      // A bare URL: fetch the texture table once. The files' root stays the folder it is written to.
      const fs::path local =
          (c.disk_cache_dir.empty() ? fs::temp_directory_path() / ("texstream-origin-" + std::to_string(::getpid()))
                                    : fs::path(c.disk_cache_dir)) /
          "scene";
      Result<std::string> table = stack->http->fetch_all(kTextureTable);
      // kPeerDead: the origin did not answer (texstream-server exits with its "storage unavailable" status,
      // which the renderer retries like a crash); an answer that is wrong keeps its own code.
      if (!table.ok()) {
        const ErrorCode code = table.error().code == ErrorCode::kIo || table.error().code == ErrorCode::kTimeout ||
                                       table.error().code == ErrorCode::kUnavailable
                                   ? ErrorCode::kPeerDead
                                   : table.error().code;
        return make_error(code, "storage.origin: " + table.error().message);
      }
      std::error_code ec;
      fs::create_directories(local, ec);
      std::ofstream out(local / kTextureTable, std::ios::binary | std::ios::trunc);
      out.write(table->data(), static_cast<std::streamsize>(table->size()));
      if (!out) return make_error(ErrorCode::kIo, "cannot write '" + (local / kTextureTable).string() + "'");
      stack->http = std::move(HttpStorage::create(c.origin, local, http_options(c))).value();
      stack->scene_dir = local;
    }
    origin = stack->http.get();
  } else {
    stack->scene_dir = c.origin.empty() ? scene_dir : fs::path(c.origin);
    stack->local = std::make_unique<PosixStorage>();
    origin = stack->local.get();
  }
  if (c.slow_enabled) {
    const SlowStorageParams p = slow_params(c);
    if (Status s = validate(p); !s.ok()) return s.error();
    stack->slow = std::make_unique<SlowStorage>(*origin, p);
    origin = stack->slow.get();
  }
  if (!c.disk_cache_dir.empty()) {
    if (c.disk_cache_bytes <= 0) return make_error(ErrorCode::kInvalidArgument, "storage.disk_cache_bytes must be > 0");
    Result<std::unique_ptr<DiskCache>> cache =
        DiskCache::open(c.disk_cache_dir, static_cast<uint64_t>(c.disk_cache_bytes), c.disk_cache_policy);
    if (!cache.ok()) return cache.error();
    stack->disk_cache = std::move(cache).value();
    stack->caching = std::make_unique<CachingStorage>(*origin, *stack->disk_cache, stack->scene_dir);
    origin = stack->caching.get();
  }
  stack->top = origin;
  return stack;
}

}  // namespace texstream::server
