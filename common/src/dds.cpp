#include "texstream/common/dds.hpp"

#include <cstring>

#include "texstream/common/contract.hpp"

namespace texstream::scene {

namespace {

using namespace dds_field;

constexpr uint32_t kDdsMagic = 0x20534444u;  // "DDS "
constexpr uint32_t kDdsdCaps = 0x1u, kDdsdHeight = 0x2u, kDdsdWidth = 0x4u, kDdsdPitch = 0x8u,
                   kDdsdPixelFormat = 0x1000u, kDdsdMipMapCount = 0x20000u, kDdsdLinearSize = 0x80000u,
                   kDdsdDepth = 0x800000u;
constexpr uint32_t kDdpfAlphaPixels = 0x1u, kDdpfFourCC = 0x4u, kDdpfRgb = 0x40u;
constexpr uint32_t kDdsCapsComplex = 0x8u, kDdsCapsTexture = 0x1000u, kDdsCapsMipMap = 0x400000u;
constexpr uint32_t kCaps2Cubemap = 0x200u;
constexpr uint32_t kCaps2Volume = 0x200000u;
constexpr uint32_t kFourCCDxt1 = 0x31545844u;  // "DXT1"
constexpr uint32_t kFourCCDxt5 = 0x35545844u;  // "DXT5"
constexpr uint32_t kFourCCDx10 = 0x30315844u;  // "DX10"
constexpr uint32_t kDxgiR8G8B8A8Unorm = 28, kDxgiR8G8B8A8UnormSrgb = 29;
constexpr uint32_t kDxgiBc1Unorm = 71, kDxgiBc1UnormSrgb = 72;
constexpr uint32_t kDxgiBc3Unorm = 77, kDxgiBc3UnormSrgb = 78;
constexpr uint32_t kDxgiBc7Unorm = 98, kDxgiBc7UnormSrgb = 99;
constexpr uint32_t kDx10Texture2D = 3;

uint32_t word(std::span<const std::byte> b, size_t offset) {
  uint32_t v;
  std::memcpy(&v, b.data() + offset, 4);  // little-endian host: the format's byte order
  return v;
}

void put(std::array<std::byte, kDdsHeaderBytes>& b, size_t offset, uint32_t v) {
  std::memcpy(b.data() + offset, &v, 4);  // little-endian host: the format's byte order
}

Error corrupt(const std::string& what, const std::string& why) {
  return make_error(ErrorCode::kCorrupt, what + ": DDS " + why);
}

}  // namespace

std::array<std::byte, kDdsHeaderBytes> make_dds_header(TexelFormat format, uint32_t width, uint32_t height,
                                                       uint32_t mip_count) {
  TS_ASSERT(valid_texture_extent(width, height), "DDS extent %ux%u", width, height);
  TS_ASSERT(mip_count >= 1 && mip_count <= full_mip_count(width, height), "DDS mip_count %u for %ux%u", mip_count,
            width, height);
  std::array<std::byte, kDdsHeaderBytes> h{};
  uint32_t flags = kDdsdCaps | kDdsdHeight | kDdsdWidth | kDdsdPixelFormat | kDdsdMipMapCount;
  put(h, kMagic, kDdsMagic);
  put(h, kSize, 124);
  put(h, kHeight, height);
  put(h, kWidth, width);
  put(h, kDepth, 0);
  put(h, kMipMapCount, mip_count);
  put(h, kPfSize, 32);
  TS_ASSERT(format != TexelFormat::kBc7, "a BC7 DDS needs the DX10 extension, which the generator's header has not");
  if (is_block_compressed(format)) {
    flags |= kDdsdLinearSize;
    put(h, kPitchOrLinearSize, static_cast<uint32_t>(mip_bytes(format, width, height, 0)));
    put(h, kPfFlags, kDdpfFourCC);
    put(h, kPfFourCC, format == TexelFormat::kBc1 ? kFourCCDxt1 : kFourCCDxt5);
  } else {
    TS_ASSERT(format == TexelFormat::kRgba8, "DDS format %u", static_cast<uint32_t>(format));
    flags |= kDdsdPitch;
    put(h, kPitchOrLinearSize, width * 4);
    put(h, kPfFlags, kDdpfRgb | kDdpfAlphaPixels);
    put(h, kPfBitCount, 32);
    put(h, kPfRMask, 0x000000ffu);
    put(h, kPfGMask, 0x0000ff00u);
    put(h, kPfBMask, 0x00ff0000u);
    put(h, kPfAMask, 0xff000000u);
  }
  put(h, kFlags, flags);
  put(h, kCaps, kDdsCapsTexture | (mip_count > 1 ? kDdsCapsComplex | kDdsCapsMipMap : 0u));
  return h;
}

TexelFormat DdsLayout::texel_format() const {
  return encoding == DdsEncoding::kBc1   ? TexelFormat::kBc1
         : encoding == DdsEncoding::kBc3 ? TexelFormat::kBc3
         : encoding == DdsEncoding::kBc7 ? TexelFormat::kBc7
                                         : TexelFormat::kRgba8;
}

uint64_t DdsLayout::mip_offset(uint32_t level) const {
  return data_offset + mip_chain_offset(texel_format(), width, height, level);
}

uint64_t DdsLayout::mip_size(uint32_t level) const { return mip_bytes(texel_format(), width, height, level); }

Result<DdsLayout> parse_dds_layout(std::span<const std::byte> bytes, const std::string& what) {
  if (bytes.size() < kDdsHeaderBytes) {
    return corrupt(what, "file of " + std::to_string(bytes.size()) + " bytes is shorter than a header (128)");
  }
  if (word(bytes, kMagic) != kDdsMagic) return corrupt(what, "magic is not 'DDS '");
  if (word(bytes, kSize) != 124) return corrupt(what, "header size is " + std::to_string(word(bytes, kSize)));
  DdsLayout l;
  l.width = word(bytes, kWidth);
  l.height = word(bytes, kHeight);
  if (!valid_texture_extent(l.width, l.height)) {
    return corrupt(what, "extent " + std::to_string(l.width) + "x" + std::to_string(l.height) + " is outside [1, " +
                             std::to_string(kMaxTextureExtent) + "]");
  }
  const uint32_t flags = word(bytes, kFlags);
  const uint32_t caps2 = word(bytes, kCaps2);
  if ((caps2 & kCaps2Cubemap) != 0) return corrupt(what, "is a cube map, not one 2D texture");
  if ((caps2 & kCaps2Volume) != 0 || ((flags & kDdsdDepth) != 0 && word(bytes, kDepth) > 1)) {
    return corrupt(what, "is a volume texture, not one 2D texture");
  }
  const uint32_t mips = word(bytes, kMipMapCount);
  l.mip_count = (flags & kDdsdMipMapCount) != 0 && mips > 0 ? mips : 1;
  if (l.mip_count > full_mip_count(l.width, l.height)) {
    return corrupt(what, "mip count " + std::to_string(l.mip_count) + " exceeds the full chain of " +
                             std::to_string(full_mip_count(l.width, l.height)) + " for " + std::to_string(l.width) +
                             "x" + std::to_string(l.height));
  }
  l.data_offset = kDdsHeaderBytes;

  const uint32_t pf_flags = word(bytes, kPfFlags);
  const uint32_t fourcc = word(bytes, kPfFourCC);
  if ((pf_flags & kDdpfFourCC) != 0 && fourcc == kFourCCDx10) {
    if (bytes.size() < kDdsMaxHeaderBytes) {
      return corrupt(what, "file of " + std::to_string(bytes.size()) + " bytes ends inside the DX10 header (148)");
    }
    if (word(bytes, kDx10Dimension) != kDx10Texture2D) return corrupt(what, "DX10 resource is not a 2D texture");
    if (word(bytes, kDx10ArraySize) != 1) {
      return corrupt(what, "DX10 array of " + std::to_string(word(bytes, kDx10ArraySize)) + " textures");
    }
    l.data_offset = kDdsMaxHeaderBytes;
    const uint32_t dxgi = word(bytes, kDx10Format);
    l.encoding = dxgi == kDxgiBc1Unorm || dxgi == kDxgiBc1UnormSrgb             ? DdsEncoding::kBc1
                 : dxgi == kDxgiBc3Unorm || dxgi == kDxgiBc3UnormSrgb           ? DdsEncoding::kBc3
                 : dxgi == kDxgiBc7Unorm || dxgi == kDxgiBc7UnormSrgb           ? DdsEncoding::kBc7
                 : dxgi == kDxgiR8G8B8A8Unorm || dxgi == kDxgiR8G8B8A8UnormSrgb ? DdsEncoding::kRgba8
                                                                                : DdsEncoding::kOther;
  } else if ((pf_flags & kDdpfFourCC) != 0) {
    l.encoding = fourcc == kFourCCDxt1   ? DdsEncoding::kBc1
                 : fourcc == kFourCCDxt5 ? DdsEncoding::kBc3
                                         : DdsEncoding::kOther;
  } else if ((pf_flags & kDdpfRgb) != 0 && word(bytes, kPfBitCount) == 32 && word(bytes, kPfRMask) == 0x000000ffu &&
             word(bytes, kPfGMask) == 0x0000ff00u && word(bytes, kPfBMask) == 0x00ff0000u &&
             word(bytes, kPfAMask) == 0xff000000u) {
    l.encoding = DdsEncoding::kRgba8;
  } else {
    l.encoding = DdsEncoding::kOther;  // BGRA, RGB without alpha, luminance, ...: OpenImageIO decodes it
  }
  return l;
}

}  // namespace texstream::scene
