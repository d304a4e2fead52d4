#pragma once
// What the fuzzers share: an invariant check that traps (libFuzzer keeps the input), and a Storage over the fuzz
// input's bytes for the server's file readers: every path the reader asks for is the input (or, with `extension`
// set, only paths with that extension; the others do not exist).
#include <algorithm>
#include <cstring>
#include <filesystem>
#include <memory>
#include <span>
#include <string>

#include "texstream/server/storage/storage.hpp"

namespace texstream::fuzz {

inline void check(bool ok) {
  if (!ok) __builtin_trap();
}

class MemoryFile : public server::StorageFile {
 public:
  explicit MemoryFile(std::span<const std::byte> b) : bytes_(b) {}
  Result<uint64_t> read_at(std::span<std::byte> out, uint64_t offset) override {
    if (offset >= bytes_.size()) return uint64_t{0};
    const uint64_t n = std::min<uint64_t>(out.size(), bytes_.size() - offset);
    std::memcpy(out.data(), bytes_.data() + offset, n);
    return n;
  }
  Result<uint64_t> size() override { return uint64_t{bytes_.size()}; }

 private:
  std::span<const std::byte> bytes_;
};

class MemoryStorage : public server::Storage {
 public:
  std::span<const std::byte> bytes;
  std::string extension;  // empty: every path
  Result<std::unique_ptr<server::StorageFile>> open(const std::filesystem::path& path) override {
    if (!extension.empty() && path.extension() != extension)
      return make_error(ErrorCode::kNotFound, "no " + path.string());
    return std::unique_ptr<server::StorageFile>(std::make_unique<MemoryFile>(bytes));
  }
};

}  // namespace texstream::fuzz
