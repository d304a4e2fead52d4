#pragma once
// Where texture bytes come from. The server reads through this interface only, so a test can inject faults
// (missing files, short reads, I/O errors, delays) and a later issue can add an http(s) origin, a disk cache
// or a slow-storage emulation behind the same two calls (DESIGN.md "Texture server": tiers).
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>

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
  // The object's size in bytes (OpenImageIO's readers seek relative to the end). Errors: kIo.
  virtual Result<uint64_t> size() = 0;
};

// Thread-safe: workers open files concurrently.
class Storage {
 public:
  virtual ~Storage() = default;
  // Errors: kNotFound when there is no such object, kIo for any other failure; messages name the path.
  virtual Result<std::unique_ptr<StorageFile>> open(const std::filesystem::path& path) = 0;
};

}  // namespace texstream::server
