#pragma once
// Full-reference image error of a rendered frame against its reference frame (DESIGN "Determinism and
// measurement", seed 004 §4.1 / Appendix A.1): MSE and PSNR over the R, G, B channels, and the mean SSIM of
// Wang et al. 2004 on luma. Pure functions: no Vulkan, no I/O, no clock.
#include <cstdint>
#include <span>
#include <vector>

#include "texstream/common/result.hpp"

namespace texstream::render {

// An 8-bit RGBA image, rows top to bottom, tightly packed (width * 4 bytes per row); alpha is ignored.
struct RgbaView {
  std::span<const std::byte> pixels;
  uint32_t width = 0;
  uint32_t height = 0;
};

struct ImageError {
  double mse = 0;      // mean over R, G, B of the squared difference, 0..255 units
  double psnr_db = 0;  // 10 log10(255² / mse), kPsnrCapDb for identical images
  double ssim = 1;     // mean SSIM over the luma of the whole frame
};

// PSNR of identical frames is infinite; a finite cap keeps averages, JSON and plots meaningful. 100 dB is an
// MSE of 6.5e-6, far below one 8-bit step on any pixel of a 16 K frame. The tree's one PSNR (chaos, benches).
inline constexpr double kPsnrCapDb = 100.0;

// SSIM constants of Wang et al. 2004 (§III.C and their reference ssim_index.m): an 11x11 circular-symmetric
// Gaussian window of σ = 1.5 samples normalised to unit sum, K1 = 0.01, K2 = 0.03, dynamic range L = 255.
inline constexpr int kSsimWindow = 11;
inline constexpr double kSsimSigma = 1.5;
inline constexpr double kSsimK1 = 0.01;
inline constexpr double kSsimK2 = 0.03;
inline constexpr double kSsimRange = 255.0;

double psnr_db(double mse);

// Mean squared error over R, G, B. Contract: same size, pixels.size() == width * height * 4.
double mse_rgb(const RgbaView& a, const RgbaView& b);

// Luma by ITU-R BT.601 (0.299 R + 0.587 G + 0.114 B), as MATLAB's rgb2gray that Wang et al.'s code applies
// to colour images; computed on the stored (sRGB-encoded) values.
std::vector<float> luma(const RgbaView& image);

// Mean of the SSIM map over the 'valid' region (windows wholly inside the image, as filter2(..., 'valid') in
// ssim_index.m): (w - 10) x (h - 10) windows. Fails if the image is smaller than one window or the sizes
// differ. The Gaussian filtering is separable (rows, then columns), in double.
Result<double> ssim(std::span<const float> a, std::span<const float> b, uint32_t width, uint32_t height);
// The SSIM map itself: one value per 'valid' window, (w - 10) x (h - 10), rows top to bottom.
Result<std::vector<double>> ssim_map(std::span<const float> a, std::span<const float> b, uint32_t width,
                                     uint32_t height);
// Seed 004 §4.2.3.1's WSSIM: the SSIM map's mean with each window weighted by its midpoint's distance to the
// frame's centre, 1 - r / r_max (1 at the centre, 0 at the corners; the thesis gives no formula, this is ours).
double wssim(std::span<const double> map, uint32_t width, uint32_t height);

// MSE, PSNR and SSIM of `image` against `reference`; fails (naming both sizes) if they differ.
Result<ImageError> compare_images(const RgbaView& image, const RgbaView& reference);

}  // namespace texstream::render
