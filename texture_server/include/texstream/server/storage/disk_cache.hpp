#pragma once
// The local disk cache of ranges fetched from a remote or slow origin: seed 002 §3.2's third tier, the one the
// Meta-texture Server tends. Keys are "<relative path>@<offset>+<length>" (the server always reads the same
// ranges of a file: the DDS header and each mip's byte range), values the bytes the origin returned.
//
// On disk, in `dir`:
//   lock            flock(LOCK_EX | LOCK_NB) for the cache's life, holding the owner's pid: a second server on
//                   the same folder is refused with a message naming the folder and that pid (sharing a folder
//                   safely would need cross-process index updates; refusing is simpler and cannot corrupt).
//   entries/*.bin   one file per entry: magic, payload length, XXH3-64 checksum of key + payload, key, payload.
//                   Written to a temporary name and renamed, so a reader never sees a half-written entry under
//                   its name; the checksum still guards against torn writes after a crash and bit rot. Every
//                   read verifies it: a corrupt entry is deleted and reported as a miss, never served.
//   index           an append-only journal ("I seq size key", "T seq key" for LRU touches, "E key"), each line
//                   ending in its own checksum. Replayed at open (so the cache survives a restart, LRU order
//                   included); a torn or corrupt line ends the replay there. Entries whose files are missing or
//                   the wrong size are dropped, files no line names are deleted, and the journal is rewritten
//                   compactly (temporary file + rename).
// Eviction keeps the disk space of the entries within the budget: each entry counts its file (header, key,
// payload) rounded up to whole blocks of the file system, so a 148-byte DDS header entry counts 4 KiB, what
// it takes on disk. (Counting payload bytes alone let a cache of many small mips take tens of times its
// budget.) LRU (a hit refreshes an entry) or FIFO (seed 002's: insertion order only). The budget is what
// storage.disk_cache_bytes asks for, lowered (with a warning) to what the folder's file system can hold: at
// open, to the free space plus what the entries already take, less a sixteenth; and whenever an entry's write
// fails with ENOSPC/EDQUOT (another process filled the disk), to seven eighths of what the cache takes,
// evicting the rest so that new entries fit again. Before, a budget larger than the disk left every later
// entry unwritten, with one warning per attempt. Thread-safe: workers read and insert concurrently; file I/O
// runs outside the lock.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"

namespace texstream::server {

// storage.disk_cache_policy (lru or fifo): the config key's enum, named with its table in config.hpp.
using texstream::DiskCachePolicy;

struct DiskCacheCounters {
  std::atomic<uint64_t> hits{0};
  std::atomic<uint64_t> misses{0};
  std::atomic<uint64_t> bytes_hit{0};
  std::atomic<uint64_t> inserts{0};
  std::atomic<uint64_t> bytes_inserted{0};
  std::atomic<uint64_t> evictions{0};
  std::atomic<uint64_t> corrupt_dropped{0};  // entries whose checksum, key or size did not match
};

class DiskCache {
 public:
  // Creates `dir` if needed, takes its lock and loads the index. Errors: kInvalidArgument when another process
  // holds the folder (names it and its pid), kIo for file-system failures (naming the path).
  static Result<std::unique_ptr<DiskCache>> open(const std::filesystem::path& dir, uint64_t budget_bytes,
                                                 DiskCachePolicy policy);
  ~DiskCache();
  DiskCache(const DiskCache&) = delete;
  DiskCache& operator=(const DiskCache&) = delete;

  static std::string key_of(const std::string& relative_path, uint64_t offset, uint64_t length);

  // Copies the entry into `out` (which must hold it) and returns its length; nullopt on a miss or a corrupt
  // entry (dropped). LRU: refreshes the entry.
  std::optional<uint64_t> read(const std::string& key, std::span<std::byte> out);
  bool contains(const std::string& key) const;
  // Stores `data` under `key` (replacing an older entry) and evicts down to the budget. Data larger than the
  // budget, or a key with a newline or tab, is not stored. A write failure is logged and the entry skipped.
  void insert(const std::string& key, std::span<const std::byte> data);

  // Disk space the entries take (what the budget bounds), and what one entry of this key and payload takes.
  uint64_t bytes() const;
  uint64_t footprint(const std::string& key, uint64_t payload_bytes) const;
  size_t entries() const;
  uint64_t budget() const { return budget_.load(std::memory_order_relaxed); }  // relaxed: a gauge
  const DiskCacheCounters& counters() const { return counters_; }
  const std::filesystem::path& dir() const { return dir_; }

 private:
  struct Entry {
    uint64_t seq;   // position in order_: insertion (FIFO) or last use (LRU)
    uint64_t size;  // payload bytes
  };
  DiskCache(std::filesystem::path dir, uint64_t budget, DiskCachePolicy policy, int lock_fd);
  Status load_index();
  Status rewrite_index_locked();
  void append_locked(const std::string& line);
  void erase_locked(const std::string& key, bool journal);
  void evict_locked();
  // An entry's write ran out of space: lower the budget below what is held (see the header comment).
  void shrink_for_space_locked();
  std::filesystem::path entry_path(const std::string& key) const;

  const std::filesystem::path dir_;
  // Written under mutex_; read without it by insert()'s size check.
  std::atomic<uint64_t> budget_;
  const DiskCachePolicy policy_;
  const int lock_fd_;
  mutable std::mutex mutex_;
  std::unordered_map<std::string, Entry> entries_;
  std::map<uint64_t, std::string> order_;  // seq → key, oldest first
  uint64_t next_seq_ = 1;
  uint64_t bytes_ = 0;
  int journal_fd_ = -1;
  uint64_t journal_lines_ = 0;
  bool append_failed_ = false;
  uint64_t block_ = 4096;  // the file system's block size (statvfs f_bsize at open)  // the last journal append failed
                           // (logged once until one succeeds again)
  DiskCacheCounters counters_;
};

}  // namespace texstream::server
