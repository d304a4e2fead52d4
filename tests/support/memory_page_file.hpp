#pragma once
// A small page file (common/page_file.hpp) built in memory, for tests and fuzzers that need one without the
// baker: a square RGBA8 image of 8 << (levels - 1) texels in 8-texel pages without borders, every page
// stored (256 bytes each), every byte of the page at absolute index i equal to (i * 16 + offset) & 0xff.
// Header-only; included as "../support/memory_page_file.hpp".
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>
#include <vector>

#include "texstream/common/page_file.hpp"

namespace texstream::test {

struct MemoryPageFile {
  std::vector<std::byte> bytes;                 // the whole file
  std::shared_ptr<const pages::PageFile> file;  // its header and index, loaded (null if loading failed)

  explicit MemoryPageFile(uint32_t levels = 2) {
    const uint32_t side = 8u << (levels - 1);
    auto g = pages::PageGeometry::make(TexelFormat::kRgba8, side, side, 8, 0, pages::PageWrap::kClamp, "memory");
    if (!g.ok()) return;
    const uint64_t count = g->page_slots();
    const pages::PageFileHeader h = pages::make_page_file_header(*g, count);
    bytes.resize(h.data_offset + count * g->page_bytes());
    std::memcpy(bytes.data(), &h, sizeof h);
    for (uint64_t i = 0; i < count; ++i) {
      const pages::PageIndexEntry e{h.data_offset + i * g->page_bytes(), static_cast<uint32_t>(g->page_bytes()), 1.0f};
      std::memcpy(bytes.data() + h.index_offset + i * sizeof e, &e, sizeof e);
      for (uint64_t b = 0; b < g->page_bytes(); ++b) bytes[e.offset + b] = std::byte((i * 16 + b) & 0xff);
    }
    const pages::PageFile::ReadAt read = [this](std::span<std::byte> out, uint64_t offset) -> Result<uint64_t> {
      if (offset > bytes.size() || out.size() > bytes.size() - offset) return uint64_t{0};
      std::memcpy(out.data(), bytes.data() + offset, out.size());
      return out.size();
    };
    auto f = pages::PageFile::load(read, bytes.size(), "memory");
    if (f.ok()) file = std::make_shared<const pages::PageFile>(std::move(f).value());
  }

  // The stored bytes of page `p` (which must be stored).
  std::span<const std::byte> page(pages::PageId p) const {
    const auto e = file->entry(p);
    return std::span<const std::byte>(bytes).subspan(e->offset, e->bytes);
  }
};

}  // namespace texstream::test
