#include "image_psnr.hpp"

#include <OpenImageIO/imageio.h>

#include <cstddef>
#include <vector>

#include "texstream/render/measure/image_metrics.hpp"

namespace texstream::chaos {

namespace {
struct Image {
  uint32_t width = 0, height = 0;
  std::vector<std::byte> rgba;
  render::RgbaView view() const { return {rgba, width, height}; }
};

// RGBA8 (alpha left 0: the metrics ignore it) from the file's first three channels.
Result<Image> read_rgba(const std::filesystem::path& file) {
  auto in = OIIO::ImageInput::open(file.string());
  if (!in) return make_error(ErrorCode::kIo, "cannot open image '" + file.string() + "': " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.nchannels < 3)
    return make_error(ErrorCode::kCorrupt, "image '" + file.string() + "' has fewer than 3 channels");
  Image img;
  img.width = static_cast<uint32_t>(spec.width);
  img.height = static_cast<uint32_t>(spec.height);
  std::vector<uint8_t> all(static_cast<size_t>(spec.width) * spec.height * spec.nchannels);
  const bool ok = in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UINT8, all.data());
  if (!ok || in->has_error())
    return make_error(ErrorCode::kCorrupt, "cannot read image '" + file.string() + "': " + in->geterror());
  const size_t pixels = size_t{img.width} * img.height;
  img.rgba.assign(pixels * 4, std::byte{0});
  for (size_t p = 0; p < pixels; ++p)
    for (size_t c = 0; c < 3; ++c) img.rgba[p * 4 + c] = static_cast<std::byte>(all[p * spec.nchannels + c]);
  return img;
}
}  // namespace

Result<double> image_psnr_db(const std::filesystem::path& a, const std::filesystem::path& b) {
  auto ia = read_rgba(a);
  if (!ia) return ia.error();
  auto ib = read_rgba(b);
  if (!ib) return ib.error();
  if (ia->width != ib->width || ia->height != ib->height) {
    return make_error(ErrorCode::kInvalidArgument,
                      "images '" + a.string() + "' and '" + b.string() + "' differ in size");
  }
  return render::psnr_db(render::mse_rgb(ia->view(), ib->view()));
}

}  // namespace texstream::chaos
