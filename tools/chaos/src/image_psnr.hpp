#pragma once
// PSNR of two image files of the same size, read with OpenImageIO and measured by the renderer's one PSNR
// (render/measure/image_metrics.hpp): over R, G, B, capped at kPsnrCapDb (100 dB) for identical images.
#include <filesystem>

#include "texstream/common/result.hpp"

namespace texstream::chaos {

Result<double> image_psnr_db(const std::filesystem::path& a, const std::filesystem::path& b);

}  // namespace texstream::chaos
