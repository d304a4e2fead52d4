#pragma once
// The DDS header, written and read in one place. The writer makes the generator's files (legacy header, no DX10
// extension, mips finest first). The one parser reads DDS files from any tool: legacy headers (FourCC DXT1, DXT5,
// 32-bit RGBA masks) and the DX10 extension (DXGI BC1 / BC3 / BC7 / R8G8B8A8). Mips are stored finest first, back to
// back, after the header (128 bytes, or 148 with the DX10 extension), so one mip is one byte range (seed 000 §3.5: read
// exactly that). Encodings that cannot be served raw (BGRA, 24-bit, BC4/5/6, ...) are reported as kOther: the server's
// loader then decodes that mip through OpenImageIO into RGBA8. Pure parsing, no I/O.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::scene {

inline constexpr uint64_t kDdsHeaderBytes = 128;     // "DDS " + DDS_HEADER (124 bytes), no DX10 extension
inline constexpr uint64_t kDdsMaxHeaderBytes = 148;  // the legacy header plus the DX10 extension

// Field offsets in bytes from the start of the file (the "DDS " magic is bytes 0-3), from Microsoft's
// DDS_HEADER / DDS_PIXELFORMAT / DDS_HEADER_DXT10 documentation. Tools that damage headers on purpose use them.
namespace dds_field {
inline constexpr size_t kMagic = 0, kSize = 4, kFlags = 8, kHeight = 12, kWidth = 16, kPitchOrLinearSize = 20,
                        kDepth = 24, kMipMapCount = 28, kPfSize = 76, kPfFlags = 80, kPfFourCC = 84, kPfBitCount = 88,
                        kPfRMask = 92, kPfGMask = 96, kPfBMask = 100, kPfAMask = 104, kCaps = 108, kCaps2 = 112;
inline constexpr size_t kDx10Format = 128, kDx10Dimension = 132, kDx10ArraySize = 140;
}  // namespace dds_field

// The generator's header for a `format` texture of `mip_count` levels.
std::array<std::byte, kDdsHeaderBytes> make_dds_header(TexelFormat format, uint32_t width, uint32_t height,
                                                       uint32_t mip_count);

enum class DdsEncoding : uint8_t {
  kBc1,    // BC1/DXT1 blocks: served as they are
  kBc3,    // BC3/DXT5 blocks: served as they are to a bc3 texture
  kBc7,    // BC7 blocks (DX10 extension): served as they are to a bc7 texture
  kRgba8,  // 32-bit R,G,B,A bytes in this order: served as they are
  kOther,  // anything else OpenImageIO may decode
};

struct DdsLayout {
  DdsEncoding encoding = DdsEncoding::kOther;
  uint32_t width = 0;
  uint32_t height = 0;
  uint32_t mip_count = 0;    // levels stored in the file (1 when the header has no mip count)
  uint64_t data_offset = 0;  // 128, or 148 with the DX10 extension

  // The texel format the blocks are in (kRgba8 for kOther, which is decoded to it).
  TexelFormat texel_format() const;
  // Byte range of `level` (< mip_count) for kBc1 / kBc3 / kRgba8.
  uint64_t mip_offset(uint32_t level) const;
  uint64_t mip_size(uint32_t level) const;
  bool operator==(const DdsLayout&) const = default;
};

// Parses the first bytes of a DDS file (`bytes` may be longer than the header; shorter is kCorrupt). Errors
// (kCorrupt) name `what` (the path) and the field: bad magic or size, zero or huge extent, cube maps, volume
// textures and arrays (one 2D texture per file is what a texture id names).
Result<DdsLayout> parse_dds_layout(std::span<const std::byte> bytes, const std::string& what);

// Where the generator's files (header of kDdsHeaderBytes) keep mip `level`, and their whole size.
inline uint64_t dds_mip_offset(TexelFormat format, uint32_t width, uint32_t height, uint32_t level) {
  return kDdsHeaderBytes + mip_chain_offset(format, width, height, level);
}
inline uint64_t dds_file_bytes(TexelFormat format, uint32_t width, uint32_t height, uint32_t mip_count) {
  return kDdsHeaderBytes + mip_chain_offset(format, width, height, mip_count);
}

}  // namespace texstream::scene
