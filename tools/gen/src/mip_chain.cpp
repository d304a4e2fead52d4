#include "mip_chain.hpp"

#include <algorithm>
#include <array>
#include <limits>

#include "colour.hpp"
#include "texstream/common/contract.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::gen {

namespace {

struct SrgbTables {
  std::array<float, 256> to_linear;
  // Linear values half-way between neighbouring 8-bit sRGB codes: the code of a linear value is the number of
  // thresholds below it, i.e. round(255 * linear_to_srgb(v)) computed exactly without pow per texel.
  // thresholds[255] = +inf is a sentinel for the forward scan in linear_to_srgb8.
  std::array<float, 256> thresholds;
  // The code of the lowest value of each of kBuckets equal slices of [0, 1]: the exact code is at most a few
  // steps above it (the slices are narrower than the code steps everywhere but in the darkest values).
  static constexpr int kBuckets = 4096;
  std::array<uint8_t, kBuckets + 1> bucket_code;
  SrgbTables() {
    for (int k = 0; k < 256; ++k) to_linear[static_cast<size_t>(k)] = srgb_to_linear(static_cast<float>(k) / 255.0f);
    for (int k = 0; k < 255; ++k)
      thresholds[static_cast<size_t>(k)] = srgb_to_linear((static_cast<float>(k) + 0.5f) / 255.0f);
    thresholds[255] = std::numeric_limits<float>::infinity();
    for (int b = 0; b <= kBuckets; ++b) {
      const float lo = static_cast<float>(b) / kBuckets;
      bucket_code[static_cast<size_t>(b)] =
          static_cast<uint8_t>(std::upper_bound(thresholds.begin(), thresholds.begin() + 255, lo) - thresholds.begin());
    }
  }
};

const SrgbTables& tables() {
  static const SrgbTables t;  // C++11 magic static: initialised once, thread-safe
  return t;
}

}  // namespace

float srgb8_to_linear(uint8_t v) { return tables().to_linear[v]; }

uint8_t linear_to_srgb8(float linear) {
  const SrgbTables& t = tables();
  const float c = std::clamp(linear, 0.0f, 1.0f);
  // Start at the code of the bucket's lower end (never above the answer), then step up past every threshold
  // below the value: the same result as counting thresholds by binary search, in one or two compares.
  unsigned code = t.bucket_code[static_cast<size_t>(c * SrgbTables::kBuckets)];
  while (t.thresholds[code] <= c) ++code;
  return static_cast<uint8_t>(code);
}

void downsample_linear(const uint32_t* src, uint32_t sw, uint32_t sh, uint32_t* dst, uint32_t dw, uint32_t dh) {
  const auto& lin = tables().to_linear;
  for (uint32_t y = 0; y < dh; ++y) {
    // Source rows covered by this output row: [floor(y*sh/dh), ceil((y+1)*sh/dh)) - two rows when halving an
    // even side, one when the side is already 1, three for the last row of an odd side.
    const uint32_t y0 = static_cast<uint32_t>(uint64_t{y} * sh / dh);
    const uint32_t y1 = static_cast<uint32_t>((uint64_t{y + 1} * sh + dh - 1) / dh);
    for (uint32_t x = 0; x < dw; ++x) {
      const uint32_t x0 = static_cast<uint32_t>(uint64_t{x} * sw / dw);
      const uint32_t x1 = static_cast<uint32_t>((uint64_t{x + 1} * sw + dw - 1) / dw);
      float r = 0, g = 0, b = 0, a = 0;
      for (uint32_t sy = y0; sy < y1; ++sy)
        for (uint32_t sx = x0; sx < x1; ++sx) {
          const uint32_t p = src[size_t{sy} * sw + sx];
          r += lin[p & 0xff];
          g += lin[(p >> 8) & 0xff];
          b += lin[(p >> 16) & 0xff];
          a += static_cast<float>(p >> 24);
        }
      const float inv = 1.0f / static_cast<float>((y1 - y0) * (x1 - x0));
      const uint32_t alpha = static_cast<uint32_t>(std::min(255.0f, a * inv + 0.5f));  // alpha is linear
      dst[size_t{y} * dw + x] = uint32_t{linear_to_srgb8(r * inv)} | uint32_t{linear_to_srgb8(g * inv)} << 8 |
                                uint32_t{linear_to_srgb8(b * inv)} << 16 | alpha << 24;
    }
  }
}

void build_mip_chain(uint32_t width, uint32_t height, std::span<uint32_t> chain) {
  const uint32_t levels = full_mip_count(width, height);
  TS_ASSERT(chain.size() * 4 == mip_chain_offset(TexelFormat::kRgba8, width, height, levels),
            "mip chain buffer of %zu texels for %ux%u", chain.size(), width, height);
  uint64_t offset = 0;
  for (uint32_t l = 1; l < levels; ++l) {
    const Extent2D s = mip_extent(width, height, l - 1), d = mip_extent(width, height, l);
    const uint64_t next = offset + uint64_t{s.width} * s.height;
    downsample_linear(chain.data() + offset, s.width, s.height, chain.data() + next, d.width, d.height);
    offset = next;
  }
}

}  // namespace texstream::gen
