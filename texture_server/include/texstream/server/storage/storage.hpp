#pragma once
// Where texture bytes come from. The server reads through this interface only, so a test can inject faults
// (missing files, short reads, I/O errors, delays), and the tiers stack behind the same calls (DESIGN.md
// "Texture server": tiers): PosixStorage or HttpStorage (origin), SlowStorage (emulation), CachingStorage
// (disk cache); storage_stack.hpp builds the stack from the [storage] configuration.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>

#include "texstream/common/result.hpp"

namespace texstream::server {

// One opened object. Used by one thread at a time.
class StorageFile {
 public:
  virtual ~StorageFile() = default;
  // Reads up to out.size() bytes at `offset`. Returns the bytes read: fewer than asked only when the object
  // ends before offset + out.size() (a caller that needs all of them treats that as truncation). Errors:
  // kIo (with the path and the reason).
  virtual Result<uint64_t> read_at(std::span<std::byte> out, uint64_t offset) = 0;
  // Reads the consecutive bytes from `offset` on into `parts`, one after another (MipLoader's coarse-tail
  // read: several mips that lie back to back, each into its own cache payload). Returns the bytes read, as
  // read_at(). This default reads part by part through read_at(), so every wrapper (rate limit, disk cache,
  // fault injection) sees the same reads; PosixStorage makes it one preadv().
  virtual Result<uint64_t> read_scatter_at(std::span<const std::span<std::byte>> parts, uint64_t offset) {
    uint64_t done = 0;
    for (const std::span<std::byte> part : parts) {
      Result<uint64_t> got = read_at(part, offset + done);
      if (!got.ok()) return got.error();
      done += *got;
      if (*got < part.size()) break;  // the object ends here
    }
    return done;
  }
  // The object's size in bytes (OpenImageIO's readers seek relative to the end). Errors: kIo.
  virtual Result<uint64_t> size() = 0;
  // True when the object lives on a far or slow origin (http, slow-storage emulation): reads may take long,
  // so the server runs them on its bounded remote-fetch workers, never on the workers that serve local reads
  // (seed 002 §3.2: access time is bimodal; a slow fetch must not hold up a fast hit).
  virtual bool remote() const { return false; }
  // Opened by its first read (Storage::open_lazy): "no such file" comes from a read as kNotFound.
  virtual bool lazy() const { return false; }
  // True when read_at(offset, bytes) would be answered on this machine (a local file, a disk-cache entry)
  // without waiting for a remote origin. A hint: the read may still go remote (an entry evicted meanwhile).
  virtual bool local(uint64_t offset, uint64_t bytes) {
    (void)offset;
    (void)bytes;
    return !remote();
  }
};

// Thread-safe: workers open files concurrently.
class Storage {
 public:
  virtual ~Storage() = default;
  // Errors: kNotFound when there is no such object, kIo for any other failure; messages name the path.
  virtual Result<std::unique_ptr<StorageFile>> open(const std::filesystem::path& path) = 0;
  // open() of a path given as text. The server's loads name files this way: making a std::filesystem::path
  // splits the text into components, an allocation per component, once per file opened (texstream-bench
  // server, misses, perf: ~3 % of the dispatcher). This default makes the path and calls open(), so every
  // storage behaves as through open(); PosixStorage opens the text as it is.
  virtual Result<std::unique_ptr<StorageFile>> open_text(const std::string& path) {
    return open(std::filesystem::path(path));
  }
  // open_text() for a caller that can take "no such file" from the first read instead of from the open
  // (kNotFound there): PosixStorage then opens, reads and closes in one io_uring submission (uring_reader.hpp)
  // and makes no system call here. This default opens at once.
  virtual Result<std::unique_ptr<StorageFile>> open_lazy(const std::string& path) { return open_text(path); }
  // Makes reads in progress (a slow http transfer, a retry back-off, an emulated stall) end soon with an
  // error, and new ones fail at once, until resume(): a server that stops joins its remote-fetch workers
  // without waiting out storage.request_timeout_ms, and the process may serve the next renderer after
  // resume(). Wrappers forward both to what they wrap.
  virtual void cancel_all() {}
  virtual void resume() {}
};

}  // namespace texstream::server
