#pragma once
// texstream-bench pages, step 3b: the seams on the GPU. texstream-gen makes a small city whose ground is an RGBA8
// page file; texstream-render draws its camera path twice in lock-step with every page and mip each frame wants
// loaded first (render.load_wanted_before_drawing): once through the page cache (ground.frag), once from one
// ordinary mipmapped texture (pages.reference). The largest channel difference over every pixel of every frame
// is the GPU's seams_max_abs_diff (tests/integration/render_ground_test.cpp checks the same on lavapipe).
#include <cstdint>
#include <filesystem>
#include <string>

namespace texstream::bench {

struct GpuSeams {
  bool ran = false;
  std::string why;  // why not, when !ran
  std::string device;
  uint64_t frames = 0;
  uint64_t ground_pixels = 0;  // pixels whose two runs differ from the sky (the ground and the meshes)
  double max_abs_diff = 0;     // 0-255, largest over pixels, frames and RGB channels
};

// `device`: render.device (a substring of the Vulkan device name; "llvmpipe" here, "NVIDIA" on the GPU machine).
GpuSeams gpu_seams(const std::filesystem::path& work, const std::string& device, bool quick);

}  // namespace texstream::bench
