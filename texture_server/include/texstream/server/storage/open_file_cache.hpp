#pragma once
// Texture files kept open between misses of the same texture. A texture's mips arrive as separate requests
// (Algorithm 1: one mip per texture per cycle, coarsest first), and an open() + close() per mip cost more than
// reading a small mip itself (texstream-bench server: ~17 us per miss on the 2-core machine, against ~8 us for
// a whole-file read() of the same texture).
//
// A file is checked out while a worker reads it (take) and handed back afterwards (give_back), so a
// StorageFile is never used by two threads at once (storage.hpp's contract) — two workers on the same texture
// at the same time simply open it twice. Bounded: at most `capacity` files stay open, the least recently used
// is closed first. Files are assumed not to change while the server runs (texture_file_index.hpp); a caller
// that finds a file shorter than expected drops it instead of handing it back. Thread-safe; files are closed
// outside the lock (close is a syscall).
#include <cstdint>
#include <filesystem>
#include <list>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>

#include "texstream/common/ids.hpp"
#include "texstream/server/storage/storage.hpp"

namespace texstream::server {

struct OpenTextureFile {
  std::string path;  // as text (Storage::open_text): for messages only
  std::unique_ptr<StorageFile> file;
};

class OpenFileCache {
 public:
  // 256: well under the usual soft RLIMIT_NOFILE of 1024 (the segment, pidfds and logging need a few), and
  // more textures than a streaming cycle's 256 requests (stream.max_requests_in_flight) can name.
  static constexpr uint32_t kDefaultCapacity = 256;

  explicit OpenFileCache(uint32_t capacity = kDefaultCapacity) : capacity_(capacity) {}

  // The texture's open file, removed from the cache (the caller owns it until give_back), or nullopt.
  std::optional<OpenTextureFile> take(TextureId id);
  // Keeps `file` open for the next miss of `id`. If the cache already holds a file for `id` (another worker
  // opened it meanwhile) or capacity is 0, `file` is closed instead.
  void give_back(TextureId id, OpenTextureFile file);
  uint32_t size() const;

 private:
  struct Entry {
    OpenTextureFile file;
    std::list<uint32_t>::iterator lru;  // position in lru_ (front = most recent)
  };
  const uint32_t capacity_;
  mutable std::mutex mutex_;
  std::unordered_map<uint32_t, Entry> open_;
  std::list<uint32_t> lru_;
};

}  // namespace texstream::server
