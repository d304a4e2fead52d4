#pragma once
// Where each mip of a DDS file lies, for DDS files from any tool (not only texstream-gen): legacy headers
// (FourCC DXT1, 32-bit RGBA masks) and the DX10 extension (DXGI BC1 / R8G8B8A8). Mips are stored finest
// first, back to back, after the header (128 bytes, or 148 with the DX10 extension), so one mip is one byte
// range (seed 000 §3.5: read exactly that). Encodings we cannot cut raw (BGRA, 24-bit, DXT5, ...) are
// reported as kOther: the loader then decodes that mip through OpenImageIO into RGBA8.
// Pure parsing, no I/O.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::server {

// Enough bytes for the legacy header plus the DX10 extension.
inline constexpr uint64_t kDdsMaxHeaderBytes = 148;

enum class DdsEncoding : uint8_t {
  kBc1,    // BC1/DXT1 blocks: served as they are
  kRgba8,  // 32-bit R,G,B,A bytes in this order: served as they are
  kOther,  // anything else OpenImageIO may decode
};

struct DdsLayout {
  DdsEncoding encoding = DdsEncoding::kOther;
  uint32_t width = 0;
  uint32_t height = 0;
  uint32_t mip_count = 0;     // levels stored in the file (1 when the header has no mip count)
  uint64_t data_offset = 0;   // 128, or 148 with the DX10 extension

  // Byte range of `level` (< mip_count) for kBc1 / kRgba8.
  uint64_t mip_offset(uint32_t level) const;
  uint64_t mip_size(uint32_t level) const;
  bool operator==(const DdsLayout&) const = default;
};

// Parses the first bytes of a DDS file (`bytes` may be longer than the header; shorter is kCorrupt). Errors
// (kCorrupt) name `what` (the path) and the field: bad magic or size, zero or huge extent, cube maps, volume
// textures and arrays (one 2D texture per file is what a texture id names).
Result<DdsLayout> parse_dds_layout(std::span<const std::byte> bytes, const std::string& what);

}  // namespace texstream::server
