#include "image_psnr.hpp"

#include <OpenImageIO/imageio.h>

#include <cmath>
#include <limits>
#include <vector>

namespace texstream::chaos {

namespace {
struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;
};

Result<Image> read_rgb(const std::filesystem::path& file) {
  auto in = OIIO::ImageInput::open(file.string());
  if (!in) return make_error(ErrorCode::kIo, "cannot open image '" + file.string() + "': " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.nchannels < 3) return make_error(ErrorCode::kCorrupt, "image '" + file.string() + "' has fewer than 3 channels");
  Image img;
  img.width = spec.width;
  img.height = spec.height;
  std::vector<uint8_t> all(static_cast<size_t>(spec.width) * spec.height * spec.nchannels);
  const bool ok = in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UINT8, all.data());
  if (!ok || in->has_error()) return make_error(ErrorCode::kCorrupt, "cannot read image '" + file.string() + "': " + in->geterror());
  img.rgb.reserve(static_cast<size_t>(img.width) * img.height * 3);
  for (size_t p = 0; p < static_cast<size_t>(img.width) * img.height; ++p)
    for (int c = 0; c < 3; ++c) img.rgb.push_back(all[p * spec.nchannels + c]);
  return img;
}
}  // namespace

Result<double> image_psnr_db(const std::filesystem::path& a, const std::filesystem::path& b) {
  auto ia = read_rgb(a);
  if (!ia) return ia.error();
  auto ib = read_rgb(b);
  if (!ib) return ib.error();
  if (ia->width != ib->width || ia->height != ib->height) {
    return make_error(ErrorCode::kInvalidArgument, "images '" + a.string() + "' and '" + b.string() + "' differ in size");
  }
  double se = 0;
  for (size_t i = 0; i < ia->rgb.size(); ++i) {
    const double d = double(ia->rgb[i]) - double(ib->rgb[i]);
    se += d * d;
  }
  if (se == 0) return std::numeric_limits<double>::infinity();
  const double mse = se / static_cast<double>(ia->rgb.size());
  return 10.0 * std::log10(255.0 * 255.0 / mse);
}

}  // namespace texstream::chaos
