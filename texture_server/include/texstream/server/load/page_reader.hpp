#pragma once
// One page of a page file (common/page_file.hpp; seeds 002 §3.1, 004 §3.2.5.1) through any storage tier —
// local, http(s) origin, disk cache, slow-storage emulation: the header and index read once when the file is
// opened, then exactly one read of exactly the page's bytes per page (no read amplification beyond the index).
// The server's page requests (issue 28, item 2) read through this. Thread-safe after open().
#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "texstream/common/page_file.hpp"
#include "texstream/common/result.hpp"
#include "texstream/server/storage/storage.hpp"

namespace texstream::server {

class PageReader {
 public:
  // `path` as the storage names it (relative to its root for a remote origin). Errors name it and the field.
  static Result<std::unique_ptr<PageReader>> open(Storage& storage, const std::string& path);

  const pages::PageFile& file() const { return index_; }
  // Reads page `p` into `out` (at least page_bytes); returns the bytes read. A page that is not stored is
  // kNotFound naming the path and the page (the caller asks for its ancestor instead).
  Result<uint64_t> read(pages::PageId p, std::span<std::byte> out);

  // True when the page's bytes would be read on this machine (a local file, a disk-cache entry), not from a
  // remote or slow origin (StorageFile::local(): a hint). False for a page that is not stored.
  bool local(pages::PageId p) const;
  const std::string& path() const { return path_; }

  uint64_t index_bytes() const { return index_bytes_; }
  uint64_t page_bytes_read() const { return page_bytes_read_.load(std::memory_order_relaxed); }

 private:
  PageReader(std::string path, std::unique_ptr<StorageFile> file, pages::PageFile index, uint64_t index_bytes)
      : path_(std::move(path)), file_(std::move(file)), index_(std::move(index)), index_bytes_(index_bytes) {}
  std::string path_;
  std::unique_ptr<StorageFile> file_;
  pages::PageFile index_;
  uint64_t index_bytes_;
  std::atomic<uint64_t> page_bytes_read_{0};
};

}  // namespace texstream::server
