#pragma once
// PSNR of two images of the same size (RGB, 8 bit), read with OpenImageIO. +inf when identical.
#include <filesystem>

#include "texstream/common/result.hpp"

namespace texstream::chaos {

Result<double> image_psnr_db(const std::filesystem::path& a, const std::filesystem::path& b);

}  // namespace texstream::chaos
