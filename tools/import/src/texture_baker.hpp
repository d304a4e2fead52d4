#pragma once
// One texture of an imported scene, baked for streaming: the image decoded once (OpenImageIO), turned to linear
// light, multiplied by the material's base colour, resized to powers of two, a full mip chain built by 2x2 box
// filters in linear light (colour weighted by alpha; a cut-out's alpha rescaled per level so that it keeps the
// coverage of level 0), encoded to BC1 (stb_dxt; cut-outs as BC1 punch-through, libsquish), BC3 (stb_dxt's
// DXT5: 8-bit alpha) or kept as RGBA8, and written as the DDS file the server reads one mip at a time.
// docs/design/import.md.
#include <array>
#include <cstdint>
#include <filesystem>
#include <string>

#include "import_model.hpp"
#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::import {

struct BakeInput {
  const SourceImage* image = nullptr;       // null: a 1x1 texture of `factor`
  std::array<float, 4> factor{1, 1, 1, 1};  // linear RGBA multiplier (glTF baseColorFactor)
  bool alpha_test = false;                  // alpha is kept (binary at `cutoff` for BC1), else forced opaque
  float cutoff = 0.5f;
  TexelFormat format = TexelFormat::kBc1;
  uint32_t max_extent = 8192;  // larger images are scaled down to this
};

struct BakedTexture {
  uint32_t width = 0;  // after the resize to powers of two
  uint32_t height = 0;
  uint32_t mip_count = 0;
  uint32_t source_width = 0;
  uint32_t source_height = 0;
  uint32_t colormap = 0;  // the 1x1 level, sRGB RGBA8 (R in the low byte)
  uint64_t file_bytes = 0;
};

// The extent an image of `w` x `h` is baked at: each side the power of two nearest to it on a log scale,
// at most `max_extent`.
uint32_t baked_side(uint32_t side, uint32_t max_extent);

// Decodes, bakes and writes `dds` (its folder must exist). `scratch` is a file name the baker may use for an
// embedded image (OpenImageIO reads files). Errors name the image and what failed.
Result<BakedTexture> bake_texture(const BakeInput& in, const std::filesystem::path& dds,
                                  const std::filesystem::path& scratch);

}  // namespace texstream::import
