#pragma once
// BC1 (DXT1) compression of one mip level with stb_dxt, the format of the seed's city data (seed 000 Table 1).
#include <cstdint>
#include <span>

namespace texstream::gen {

// `rgba` holds width x height texels (R in the low byte); `out` receives mip_bytes(kBc1, w, h) bytes.
// Levels smaller than 4x4 (and the ragged edge of any level) are padded by repeating the edge texels, so the
// padding does not pull the block's endpoints towards a colour the image does not contain.
void encode_bc1(const uint32_t* rgba, uint32_t width, uint32_t height, std::span<uint8_t> out);
// BC3 (DXT5): the same colour encoding and an 8-bit alpha block per 4x4 (texstream-import's --format bc3).
void encode_bc3(const uint32_t* rgba, uint32_t width, uint32_t height, std::span<uint8_t> out);

}  // namespace texstream::gen
