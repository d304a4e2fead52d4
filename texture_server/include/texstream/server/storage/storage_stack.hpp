#pragma once
// Builds the tiers the server reads through from the [storage] configuration (issue 4):
//
//   origin  PosixStorage (storage.origin empty: scene.dir; or a folder) or HttpStorage (http(s):// URL)
//   slow    SlowStorage around the origin when storage.slow_enabled (emulated far/slow storage)
//   disk    CachingStorage + DiskCache when storage.disk_cache_dir is set
//
// The texture table: from the folder for a local origin; for an http origin from scene.dir when it has one
// (the renderer reads the same file), else fetched from <origin>/textures.bin into
// <disk_cache_dir or a temp folder>/scene/ — so a server can run against a bare URL.
#include <filesystem>
#include <memory>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"
#include "texstream/server/storage/caching_storage.hpp"
#include "texstream/server/storage/disk_cache.hpp"
#include "texstream/server/storage/http_storage.hpp"
#include "texstream/server/storage/slow_storage.hpp"
#include "texstream/server/storage/storage.hpp"

namespace texstream::server {

struct StorageStack {
  std::filesystem::path scene_dir;  // what the Server is given: the texture table's folder, the files' root
  std::unique_ptr<Storage> local;   // PosixStorage origin
  std::unique_ptr<HttpStorage> http;
  std::unique_ptr<SlowStorage> slow;
  std::unique_ptr<DiskCache> disk_cache;
  std::unique_ptr<CachingStorage> caching;
  Storage* top = nullptr;

  Storage& storage() { return *top; }
  std::string describe() const;
  ~StorageStack();  // top down: the caching layer before the cache and the origin it uses
};

// Errors name the storage.* key or the URL/path that failed.
Result<std::unique_ptr<StorageStack>> make_storage_stack(const StorageConfig& config,
                                                         const std::filesystem::path& scene_dir);

HttpOptions http_options(const StorageConfig& config);
SlowStorageParams slow_params(const StorageConfig& config);

}  // namespace texstream::server
