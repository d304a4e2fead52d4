#include "texstream/render/measure/image_metrics.hpp"

#include <array>
#include <cmath>
#include <string>

#include "texstream/common/contract.hpp"

namespace texstream::render {

namespace {

std::array<double, kSsimWindow> gaussian_window() {
  std::array<double, kSsimWindow> w{};
  double sum = 0;
  for (int i = 0; i < kSsimWindow; ++i) {
    const double x = i - kSsimWindow / 2;
    w[static_cast<size_t>(i)] = std::exp(-(x * x) / (2 * kSsimSigma * kSsimSigma));
    sum += w[static_cast<size_t>(i)];
  }
  // The 2-D window is the outer product of this 1-D one; both sum to 1.
  for (double& v : w) v /= sum;
  return w;
}

std::string size_text(uint32_t w, uint32_t h) { return std::to_string(w) + "x" + std::to_string(h); }

}  // namespace

double psnr_db(double mse) {
  if (!(mse > 0)) return kPsnrCapDb;
  return std::min(kPsnrCapDb, 10.0 * std::log10(kSsimRange * kSsimRange / mse));
}

double mse_rgb(const RgbaView& a, const RgbaView& b) {
  TS_ASSERT(a.width == b.width && a.height == b.height, "mse_rgb: sizes differ");
  const size_t n = size_t{a.width} * a.height;
  TS_ASSERT(a.pixels.size() >= n * 4 && b.pixels.size() >= n * 4, "mse_rgb: pixel span too short");
  if (n == 0) return 0;
  const auto* pa = reinterpret_cast<const uint8_t*>(a.pixels.data());
  const auto* pb = reinterpret_cast<const uint8_t*>(b.pixels.data());
  uint64_t sum = 0;  // exact: at most 255² * 3 per pixel
  for (size_t i = 0; i < n; ++i) {
    for (size_t c = 0; c < 3; ++c) {
      const int d = int{pa[i * 4 + c]} - int{pb[i * 4 + c]};
      sum += static_cast<uint64_t>(d * d);
    }
  }
  return static_cast<double>(sum) / static_cast<double>(n * 3);
}

std::vector<float> luma(const RgbaView& image) {
  const size_t n = size_t{image.width} * image.height;
  TS_ASSERT(image.pixels.size() >= n * 4, "luma: pixel span too short");
  const auto* p = reinterpret_cast<const uint8_t*>(image.pixels.data());
  std::vector<float> y(n);
  for (size_t i = 0; i < n; ++i) {
    y[i] = static_cast<float>(0.299 * p[i * 4] + 0.587 * p[i * 4 + 1] + 0.114 * p[i * 4 + 2]);
  }
  return y;
}

Result<std::vector<double>> ssim_map(std::span<const float> a, std::span<const float> b, uint32_t width,
                                     uint32_t height) {
  const size_t n = size_t{width} * height;
  if (a.size() != n || b.size() != n) {
    return make_error(ErrorCode::kInvalidArgument, "ssim: images of " + std::to_string(a.size()) + " and " +
                                                       std::to_string(b.size()) + " samples for " +
                                                       size_text(width, height));
  }
  if (width < static_cast<uint32_t>(kSsimWindow) || height < static_cast<uint32_t>(kSsimWindow)) {
    return make_error(ErrorCode::kInvalidArgument, "ssim: " + size_text(width, height) + " is smaller than one " +
                                                       std::to_string(kSsimWindow) + "x" + std::to_string(kSsimWindow) +
                                                       " window");
  }
  static const std::array<double, kSsimWindow> g = gaussian_window();
  const double c1 = (kSsimK1 * kSsimRange) * (kSsimK1 * kSsimRange);
  const double c2 = (kSsimK2 * kSsimRange) * (kSsimK2 * kSsimRange);
  const size_t ow = width - (kSsimWindow - 1);  // 'valid' output size
  const size_t oh = height - (kSsimWindow - 1);
  // Horizontal pass of the five moments (x, y, x², y², xy) into ow-wide rows, then the vertical pass.
  std::vector<std::array<double, 5>> h(ow * height);
  for (size_t r = 0; r < height; ++r) {
    const float* ra = a.data() + r * width;
    const float* rb = b.data() + r * width;
    for (size_t c = 0; c < ow; ++c) {
      std::array<double, 5> m{};
      for (size_t k = 0; k < static_cast<size_t>(kSsimWindow); ++k) {
        const double x = static_cast<double>(ra[c + k]), y = static_cast<double>(rb[c + k]), wk = g[k];
        m[0] += wk * x;
        m[1] += wk * y;
        m[2] += wk * x * x;
        m[3] += wk * y * y;
        m[4] += wk * x * y;
      }
      h[r * ow + c] = m;
    }
  }
  std::vector<double> map(ow * oh);
  for (size_t r = 0; r < oh; ++r) {
    for (size_t c = 0; c < ow; ++c) {
      std::array<double, 5> m{};
      for (size_t k = 0; k < static_cast<size_t>(kSsimWindow); ++k) {
        const auto& v = h[(r + k) * ow + c];
        for (size_t q = 0; q < 5; ++q) m[q] += g[k] * v[q];
      }
      const double mx = m[0], my = m[1];
      const double vx = m[2] - mx * mx, vy = m[3] - my * my, cxy = m[4] - mx * my;
      map[r * ow + c] = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2));
    }
  }
  return map;
}

Result<double> ssim(std::span<const float> a, std::span<const float> b, uint32_t width, uint32_t height) {
  auto map = ssim_map(a, b, width, height);
  if (!map.ok()) return map.error();
  double total = 0;
  for (double v : map.value()) total += v;
  return total / static_cast<double>(map->size());
}

double wssim(std::span<const double> map, uint32_t width, uint32_t height) {
  const uint32_t ow = width - (kSsimWindow - 1), oh = height - (kSsimWindow - 1);
  TS_ASSERT(map.size() == size_t{ow} * oh, "wssim: a map of %zu for %ux%u", map.size(), width, height);
  // A window's midpoint is its centre pixel (c + 5, r + 5); weight 1 at the frame's centre, 0 at its corners.
  const double cx = (width - 1) / 2.0, cy = (height - 1) / 2.0, rmax = std::hypot(cx, cy);
  double total = 0, weights = 0;
  for (uint32_t r = 0; r < oh; ++r)
    for (uint32_t c = 0; c < ow; ++c) {
      const double w = 1.0 - std::hypot(c + kSsimWindow / 2 - cx, r + kSsimWindow / 2 - cy) / rmax;
      total += w * map[size_t{r} * ow + c];
      weights += w;
    }
  return total / weights;
}

Result<ImageError> compare_images(const RgbaView& image, const RgbaView& reference) {
  if (image.width != reference.width || image.height != reference.height) {
    return make_error(ErrorCode::kInvalidArgument, "frame is " + size_text(image.width, image.height) +
                                                       " but its reference is " +
                                                       size_text(reference.width, reference.height));
  }
  const size_t bytes = size_t{image.width} * image.height * 4;
  if (image.pixels.size() < bytes || reference.pixels.size() < bytes) {
    return make_error(ErrorCode::kInvalidArgument, "frame or reference holds fewer than width x height x 4 bytes");
  }
  ImageError e;
  e.mse = mse_rgb(image, reference);
  e.psnr_db = psnr_db(e.mse);
  const std::vector<float> ya = luma(image), yb = luma(reference);
  auto s = ssim(ya, yb, image.width, image.height);
  if (!s) return s.error();
  e.ssim = *s;
  return e;
}

}  // namespace texstream::render
