#include "bc1_encoder.hpp"

#include <algorithm>
#include <cstring>

#include "texstream/common/contract.hpp"
#include "texstream/common/texel_format.hpp"

// The one translation unit that holds stb_dxt's implementation.
#define STB_DXT_IMPLEMENTATION
#include <stb_dxt.h>

namespace texstream::gen {

namespace {

// Blocks of `format` (BC1, or BC3 = an alpha block then a colour block, stb_dxt's alpha mode).
void encode_blocks(TexelFormat format, const uint32_t* rgba, uint32_t width, uint32_t height, std::span<uint8_t> out) {
  TS_ASSERT(out.size() == mip_bytes(format, Extent2D{width, height}), "block buffer of %zu bytes for %ux%u", out.size(),
            width, height);
  const int alpha = format == TexelFormat::kBc3 ? 1 : 0;
  const size_t step = block_bytes(format);
  const uint32_t bw = (width + 3) / 4, bh = (height + 3) / 4;
  uint32_t block[16];
  uint8_t* dst = out.data();
  for (uint32_t by = 0; by < bh; ++by)
    for (uint32_t bx = 0; bx < bw; ++bx) {
      for (uint32_t y = 0; y < 4; ++y) {
        const uint32_t sy = std::min(by * 4 + y, height - 1);
        for (uint32_t x = 0; x < 4; ++x) block[y * 4 + x] = rgba[size_t{sy} * width + std::min(bx * 4 + x, width - 1)];
      }
      unsigned char bytes[64];
      std::memcpy(bytes, block, sizeof bytes);  // RGBA byte order in memory on a little-endian host
      stb_compress_dxt_block(dst, bytes, alpha, STB_DXT_NORMAL);
      dst += step;
    }
}

}  // namespace

void encode_bc1(const uint32_t* rgba, uint32_t width, uint32_t height, std::span<uint8_t> out) {
  encode_blocks(TexelFormat::kBc1, rgba, width, height, out);
}

void encode_bc3(const uint32_t* rgba, uint32_t width, uint32_t height, std::span<uint8_t> out) {
  encode_blocks(TexelFormat::kBc3, rgba, width, height, out);
}

}  // namespace texstream::gen
