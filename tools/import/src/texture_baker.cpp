#include "texture_baker.hpp"

#include <squish.h>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <vector>

#include "bc1_encoder.hpp"
#include "mip_chain.hpp"
#include "texstream/common/dds.hpp"

namespace texstream::import {
namespace {

struct Level {
  uint32_t width = 0, height = 0;
  std::vector<float> rgba;  // linear, straight alpha
};

float srgb_to_linear(float c) { return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f); }

Result<Level> decode(const SourceImage& image, const std::filesystem::path& scratch) {
  std::filesystem::path file = image.file;
  if (file.empty()) {
    file = scratch;
    file += image.extension;
    std::ofstream f(file, std::ios::binary | std::ios::trunc);
    f.write(reinterpret_cast<const char*>(image.bytes.data()), static_cast<std::streamsize>(image.bytes.size()));
    if (!f) return make_error(ErrorCode::kIo, image.name + ": cannot write the scratch copy " + file.string());
  } else if (!std::filesystem::exists(file)) {
    return make_error(ErrorCode::kNotFound, image.name + ": no such image file");
  }
  auto in = OIIO::ImageInput::open(file.string());
  if (!in) {
    const std::string why = OIIO::geterror();
    if (image.file.empty()) std::filesystem::remove(file);
    return make_error(ErrorCode::kCorrupt, image.name + ": cannot decode: " + why);
  }
  const OIIO::ImageSpec spec = in->spec();
  const int nch = spec.nchannels;
  if (spec.width <= 0 || spec.height <= 0 || nch <= 0 || spec.depth > 1 ||
      static_cast<uint64_t>(spec.width) > kMaxTextureExtent * 4ull ||
      static_cast<uint64_t>(spec.height) > kMaxTextureExtent * 4ull)
    return make_error(ErrorCode::kUnsupported, image.name + ": extent " + std::to_string(spec.width) + "x" +
                                                   std::to_string(spec.height) + "x" + std::to_string(nch) +
                                                   " channels");
  std::vector<float> px(size_t(spec.width) * spec.height * nch);
  const bool read = in->read_image(0, 0, 0, nch, OIIO::TypeDesc::FLOAT, px.data());
  const std::string why = read ? "" : in->geterror();
  in->close();
  if (image.file.empty()) std::filesystem::remove(file);
  if (!read) return make_error(ErrorCode::kCorrupt, image.name + ": cannot decode: " + why);

  // Integer images carry sRGB-encoded colour (glTF: base colour textures are sRGB); float images are linear.
  const bool bytes = spec.format.basetype == OIIO::TypeDesc::UINT8;
  const bool encoded = bytes || spec.format.basetype == OIIO::TypeDesc::UINT16;
  // 8-bit data (k / 255 as OpenImageIO hands it over) through the exact 256-entry table, not std::pow per
  // channel: that pow was most of the time of a 256² PNG's bake.
  auto to_linear = [&](float v) {
    const float c = std::clamp(v, 0.0f, 1.0f);
    return bytes ? gen::srgb8_to_linear(static_cast<uint8_t>(std::lround(c * 255.0f))) : srgb_to_linear(c);
  };
  const int alpha_channel = spec.alpha_channel >= 0 ? spec.alpha_channel : (nch == 2 ? 1 : nch >= 4 ? 3 : -1);
  Level l;
  l.width = static_cast<uint32_t>(spec.width);
  l.height = static_cast<uint32_t>(spec.height);
  l.rgba.resize(size_t(l.width) * l.height * 4);
  for (size_t i = 0; i < size_t(l.width) * l.height; ++i) {
    const float* p = &px[i * nch];
    float c[3];
    if (nch <= 2)
      c[0] = c[1] = c[2] = p[0];
    else
      for (int k = 0; k < 3; ++k) c[k] = p[k];
    for (int k = 0; k < 3; ++k) l.rgba[i * 4 + k] = encoded ? to_linear(c[k]) : std::max(c[k], 0.0f);
    l.rgba[i * 4 + 3] = alpha_channel >= 0 ? std::clamp(p[alpha_channel], 0.0f, 1.0f) : 1.0f;
  }
  return l;
}

// Resized with OpenImageIO's filter (lanczos3 down, blackman-harris up) on premultiplied colour, so transparent
// texels lend no colour to their neighbours.
Level resize(const Level& src, uint32_t w, uint32_t h) {
  std::vector<float> pre(src.rgba);
  for (size_t i = 0; i < pre.size(); i += 4)
    for (int k = 0; k < 3; ++k) pre[i + k] *= pre[i + 3];
  OIIO::ImageBuf in(
      OIIO::ImageSpec(static_cast<int>(src.width), static_cast<int>(src.height), 4, OIIO::TypeDesc::FLOAT), pre.data());
  OIIO::ROI roi(0, static_cast<int>(w), 0, static_cast<int>(h), 0, 1, 0, 4);
  OIIO::ImageBuf out = OIIO::ImageBufAlgo::resize(in, "", 0.0f, roi, 1);
  Level l;
  l.width = w;
  l.height = h;
  l.rgba.resize(size_t(w) * h * 4);
  out.get_pixels(roi, OIIO::TypeDesc::FLOAT, l.rgba.data());
  for (size_t i = 0; i < l.rgba.size(); i += 4) {
    const float a = std::clamp(l.rgba[i + 3], 0.0f, 1.0f);
    l.rgba[i + 3] = a;
    for (int k = 0; k < 3; ++k) l.rgba[i + k] = a > 1e-6f ? std::max(l.rgba[i + k] / a, 0.0f) : 0.0f;
  }
  return l;
}

// 2x2 (or 2x1) box in linear light, colour weighted by alpha.
Level downsample(const Level& s) {
  Level d;
  d.width = std::max(1u, s.width / 2);
  d.height = std::max(1u, s.height / 2);
  d.rgba.resize(size_t(d.width) * d.height * 4);
  const uint32_t fx = s.width > 1 ? 2 : 1, fy = s.height > 1 ? 2 : 1;
  for (uint32_t y = 0; y < d.height; ++y)
    for (uint32_t x = 0; x < d.width; ++x) {
      float c[3] = {0, 0, 0}, cw[3] = {0, 0, 0}, a = 0;
      for (uint32_t j = 0; j < fy; ++j)
        for (uint32_t i = 0; i < fx; ++i) {
          const float* p = &s.rgba[(size_t(y * fy + j) * s.width + x * fx + i) * 4];
          for (int k = 0; k < 3; ++k) {
            c[k] += p[k];
            cw[k] += p[k] * p[3];
          }
          a += p[3];
        }
      const float n = static_cast<float>(fx * fy);
      float* o = &d.rgba[(size_t(y) * d.width + x) * 4];
      for (int k = 0; k < 3; ++k) o[k] = a > 1e-6f ? cw[k] / a : c[k] / n;
      o[3] = a / n;
    }
  return d;
}

double coverage(const Level& l, float cutoff) {
  size_t n = 0;
  for (size_t i = 3; i < l.rgba.size(); i += 4) n += l.rgba[i] >= cutoff;
  return static_cast<double>(n) / static_cast<double>(l.rgba.size() / 4);
}

// Scales a coarser level's alpha so that as many texels pass the alpha test as at level 0 (box-filtered
// alpha of a fence or a leaf thins out level by level otherwise). Castano, "Computing alpha mipmaps" (2010).
void keep_coverage(Level& l, double target, float cutoff) {
  float lo = 0.0f, hi = 64.0f;
  for (int it = 0; it < 16; ++it) {
    const float mid = 0.5f * (lo + hi);
    size_t n = 0;
    for (size_t i = 3; i < l.rgba.size(); i += 4) n += std::min(1.0f, l.rgba[i] * mid) >= cutoff;
    if (static_cast<double>(n) / static_cast<double>(l.rgba.size() / 4) < target)
      lo = mid;
    else
      hi = mid;
  }
  for (size_t i = 3; i < l.rgba.size(); i += 4) l.rgba[i] = std::min(1.0f, l.rgba[i] * hi);
}

// sRGB RGBA8, R in the low byte. An alpha-tested texture keeps premultiplied colour (what BC1 punch-through
// decodes to: transparent texels are black; scene.frag divides by the filtered alpha); with `binary` alpha (BC1)
// the cutoff decides each texel.
std::vector<uint32_t> to_rgba8(const Level& l, bool alpha_test, bool binary, float cutoff) {
  std::vector<uint32_t> out(size_t(l.width) * l.height);
  for (size_t i = 0; i < out.size(); ++i) {
    const float* p = &l.rgba[i * 4];
    const float a = !alpha_test ? 1.0f : binary ? (p[3] >= cutoff ? 1.0f : 0.0f) : std::clamp(p[3], 0.0f, 1.0f);
    const uint32_t a8 = static_cast<uint32_t>(std::lround(a * 255.0f));
    out[i] = uint32_t{gen::linear_to_srgb8(p[0] * a)} | uint32_t{gen::linear_to_srgb8(p[1] * a)} << 8 |
             uint32_t{gen::linear_to_srgb8(p[2] * a)} << 16 | a8 << 24;
  }
  return out;
}

}  // namespace

uint32_t baked_side(uint32_t side, uint32_t max_extent) {
  const uint32_t cap = std::max(1u, std::min(max_extent, kMaxTextureExtent));
  uint32_t p = 1;
  while (p < side && p < cap) p <<= 1;
  // p is the power of two at or above `side`; take the one below when it is nearer on a log scale.
  if (p > side && p > 1 && static_cast<double>(p) / side > static_cast<double>(side) / (p / 2)) p >>= 1;
  uint32_t capped = 1;
  while (capped * 2 <= cap) capped <<= 1;
  return std::min(p, capped);
}

Result<BakedTexture> bake_texture(const BakeInput& in, const std::filesystem::path& dds,
                                  const std::filesystem::path& scratch) {
  Level level;
  BakedTexture out;
  if (in.image) {
    auto decoded = decode(*in.image, scratch);
    if (!decoded.ok()) return decoded.error();
    level = std::move(decoded.value());
  } else {
    level.width = level.height = 1;
    level.rgba = {1, 1, 1, 1};
  }
  out.source_width = level.width;
  out.source_height = level.height;
  for (size_t i = 0; i < level.rgba.size(); i += 4) {
    for (int k = 0; k < 4; ++k) level.rgba[i + k] *= in.factor[k];
    if (!in.alpha_test) level.rgba[i + 3] = 1.0f;
  }
  const uint32_t w = baked_side(level.width, in.max_extent), h = baked_side(level.height, in.max_extent);
  if (w != level.width || h != level.height) level = resize(level, w, h);
  out.width = w;
  out.height = h;
  out.mip_count = full_mip_count(w, h);

  const bool bc1 = in.format == TexelFormat::kBc1;  // cut-outs binary (punch-through); BC3 and RGBA8 keep 8 bits
  const double coverage0 = in.alpha_test ? coverage(level, in.cutoff) : 1.0;
  std::ofstream f(dds, std::ios::binary | std::ios::trunc);
  const auto header = scene::make_dds_header(in.format, w, h, out.mip_count);
  f.write(reinterpret_cast<const char*>(header.data()), static_cast<std::streamsize>(header.size()));
  std::vector<uint8_t> blocks;
  for (uint32_t l = 0; l < out.mip_count; ++l) {
    if (l > 0) {
      level = downsample(level);
      if (in.alpha_test) keep_coverage(level, coverage0, in.cutoff);
    }
    const std::vector<uint32_t> texels = to_rgba8(level, in.alpha_test, bc1, in.cutoff);
    const uint64_t bytes = mip_bytes(in.format, level.width, level.height, 0);
    blocks.assign(bytes, 0);
    if (in.format == TexelFormat::kBc3) {
      gen::encode_bc3(texels.data(), level.width, level.height, blocks);
    } else if (!bc1) {
      std::memcpy(blocks.data(), texels.data(), bytes);
    } else if (in.alpha_test) {
      // Punch-through: squish picks BC1's 3-colour mode for blocks with a texel below alpha 128.
      squish::CompressImage(reinterpret_cast<const squish::u8*>(texels.data()), static_cast<int>(level.width),
                            static_cast<int>(level.height), blocks.data(), squish::kDxt1 | squish::kColourClusterFit);
    } else {
      gen::encode_bc1(texels.data(), level.width, level.height, blocks);
    }
    f.write(reinterpret_cast<const char*>(blocks.data()), static_cast<std::streamsize>(bytes));
    if (l + 1 == out.mip_count) out.colormap = texels[0];
  }
  f.close();
  if (!f) return make_error(ErrorCode::kIo, dds.string() + ": cannot write");
  out.file_bytes = scene::dds_file_bytes(in.format, w, h, out.mip_count);
  return out;
}

}  // namespace texstream::import
