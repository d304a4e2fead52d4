// Image error of texstream-bench path: MSE/PSNR by hand, SSIM against closed forms and against a direct
// (non-separable) evaluation of Wang et al.'s definition.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "texstream/render/measure/image_metrics.hpp"

namespace texstream::render {
namespace {

struct Image {
  uint32_t w, h;
  std::vector<std::byte> px;
  RgbaView view() const { return {px, w, h}; }
};

Image solid(uint32_t w, uint32_t h, uint8_t r, uint8_t g, uint8_t b, uint8_t a = 255) {
  Image im{w, h, std::vector<std::byte>(size_t{w} * h * 4)};
  for (size_t i = 0; i < size_t{w} * h; ++i) {
    im.px[i * 4] = std::byte{r};
    im.px[i * 4 + 1] = std::byte{g};
    im.px[i * 4 + 2] = std::byte{b};
    im.px[i * 4 + 3] = std::byte{a};
  }
  return im;
}

Image noise(uint32_t w, uint32_t h, uint32_t seed) {
  std::mt19937 rng(seed);
  Image im{w, h, std::vector<std::byte>(size_t{w} * h * 4)};
  for (auto& b : im.px) b = std::byte{static_cast<uint8_t>(rng() & 0xff)};
  return im;
}

// Wang et al. 2004 evaluated directly: for every 11x11 window wholly inside the image, the Gaussian-weighted
// means, variances and covariance, then the SSIM formula; the mean over windows.
double direct_ssim(const std::vector<float>& a, const std::vector<float>& b, uint32_t w, uint32_t h) {
  double g[11][11], sum = 0;
  for (int y = 0; y < 11; ++y)
    for (int x = 0; x < 11; ++x) sum += g[y][x] = std::exp(-((x - 5) * (x - 5) + (y - 5) * (y - 5)) / (2 * 1.5 * 1.5));
  const double c1 = std::pow(0.01 * 255, 2), c2 = std::pow(0.03 * 255, 2);
  double total = 0;
  int n = 0;
  for (uint32_t oy = 0; oy + 11 <= h; ++oy) {
    for (uint32_t ox = 0; ox + 11 <= w; ++ox) {
      double mx = 0, my = 0, xx = 0, yy = 0, xy = 0;
      for (int y = 0; y < 11; ++y) {
        for (int x = 0; x < 11; ++x) {
          const double wt = g[y][x] / sum;
          const double va = a[(oy + y) * w + ox + x], vb = b[(oy + y) * w + ox + x];
          mx += wt * va;
          my += wt * vb;
          xx += wt * va * va;
          yy += wt * vb * vb;
          xy += wt * va * vb;
        }
      }
      total += ((2 * mx * my + c1) * (2 * (xy - mx * my) + c2)) /
               ((mx * mx + my * my + c1) * (xx - mx * mx + yy - my * my + c2));
      ++n;
    }
  }
  return total / n;
}

TEST(ImageMetrics, MseOverRgbIgnoresAlpha) {
  const Image a = solid(8, 4, 10, 20, 30, 0), b = solid(8, 4, 20, 10, 30, 255);
  EXPECT_DOUBLE_EQ(mse_rgb(a.view(), b.view()), (100.0 + 100.0 + 0.0) / 3.0);
  EXPECT_DOUBLE_EQ(mse_rgb(a.view(), a.view()), 0.0);
}

TEST(ImageMetrics, PsnrOfKnownMseAndCap) {
  EXPECT_NEAR(psnr_db(100.0), 10.0 * std::log10(65025.0 / 100.0), 1e-12);  // 28.1308 dB
  EXPECT_NEAR(psnr_db(100.0), 28.1308, 1e-4);
  EXPECT_EQ(psnr_db(0.0), kPsnrCapDb);
  EXPECT_EQ(psnr_db(1e-30), kPsnrCapDb);
}

TEST(ImageMetrics, LumaIsBt601) {
  const Image a = solid(2, 2, 200, 100, 50);
  const std::vector<float> y = luma(a.view());
  ASSERT_EQ(y.size(), 4u);
  EXPECT_NEAR(y[0], 0.299 * 200 + 0.587 * 100 + 0.114 * 50, 1e-4);
}

TEST(ImageMetrics, SsimOfIdenticalImagesIsOne) {
  const Image a = noise(40, 30, 1);
  auto e = compare_images(a.view(), a.view());
  ASSERT_TRUE(e.ok());
  EXPECT_NEAR(e->ssim, 1.0, 1e-12);
  EXPECT_EQ(e->psnr_db, kPsnrCapDb);
  EXPECT_EQ(e->mse, 0.0);
}

TEST(ImageMetrics, SsimOfTwoFlatImagesIsTheLuminanceTerm) {
  // No variance and no covariance: the contrast-structure term is C2 / C2 = 1 and SSIM is the luminance term.
  const std::vector<float> a(20 * 20, 100.0f), b(20 * 20, 150.0f);
  auto s = ssim(a, b, 20, 20);
  ASSERT_TRUE(s.ok());
  const double c1 = std::pow(0.01 * 255, 2);
  EXPECT_NEAR(*s, (2 * 100.0 * 150.0 + c1) / (100.0 * 100.0 + 150.0 * 150.0 + c1), 1e-12);
}

TEST(ImageMetrics, SsimMatchesTheDirectWindowSum) {
  const Image a = noise(37, 23, 7);
  Image b = a;
  std::mt19937 rng(3);
  for (size_t i = 0; i < b.px.size(); ++i) {  // a noisy copy: SSIM well inside (0, 1)
    const int v = static_cast<int>(b.px[i]) + static_cast<int>(rng() % 61) - 30;
    b.px[i] = std::byte{static_cast<uint8_t>(std::clamp(v, 0, 255))};
  }
  const auto ya = luma(a.view()), yb = luma(b.view());
  auto s = ssim(ya, yb, 37, 23);
  ASSERT_TRUE(s.ok());
  const double expected = direct_ssim(ya, yb, 37, 23);
  EXPECT_NEAR(*s, expected, 1e-9);
  EXPECT_GT(*s, 0.05);
  EXPECT_LT(*s, 0.99);
  // Symmetric by definition.
  EXPECT_NEAR(*ssim(yb, ya, 37, 23), *s, 1e-12);
}

// WSSIM (seed 004 §4.2.3.1): 1 for identical frames; the same damage costs more at the centre than in a corner.
TEST(ImageMetrics, WssimWeighsTheCentreAboveTheCorners) {
  const uint32_t w = 64, h = 48;
  std::vector<float> ref(size_t{w} * h);
  for (size_t i = 0; i < ref.size(); ++i) ref[i] = static_cast<float>((i * 37) % 251);
  auto map = ssim_map(ref, ref, w, h);
  ASSERT_TRUE(map.ok());
  EXPECT_NEAR(wssim(map.value(), w, h), 1.0, 1e-12);
  auto damaged = [&](uint32_t x0, uint32_t y0) {
    std::vector<float> d = ref;
    for (uint32_t y = y0; y < y0 + 12; ++y)
      for (uint32_t x = x0; x < x0 + 12; ++x) d[size_t{y} * w + x] = 255.0f - d[size_t{y} * w + x];
    auto m = ssim_map(d, ref, w, h);
    EXPECT_TRUE(m.ok());
    double mean = 0;
    for (double v : m.value()) mean += v;
    mean /= static_cast<double>(m->size());
    EXPECT_NEAR(mean, ssim(d, ref, w, h).value(), 1e-12);  // ssim is the map's mean
    return std::pair{mean, wssim(m.value(), w, h)};
  };
  const auto [centre_ssim, centre_wssim] = damaged(26, 18);
  const auto [corner_ssim, corner_wssim] = damaged(0, 0);
  EXPECT_LT(centre_wssim, centre_ssim);
  EXPECT_GT(corner_wssim, corner_ssim);
  EXPECT_LT(centre_wssim, corner_wssim);
}

TEST(ImageMetrics, SsimRefusesImagesSmallerThanOneWindow) {
  const std::vector<float> a(10 * 40, 1.0f);
  auto s = ssim(a, a, 10, 40);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("10x40"), std::string::npos);
}

TEST(ImageMetrics, CompareRefusesDifferentSizes) {
  const Image a = solid(16, 16, 1, 2, 3), b = solid(16, 12, 1, 2, 3);
  auto e = compare_images(a.view(), b.view());
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message.find("16x12"), std::string::npos);
}

}  // namespace
}  // namespace texstream::render
