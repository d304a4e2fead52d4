#include "texstream/render/measure/reference_frames.hpp"

// Static: texstream-bench links this library and has its own stb_image implementation (cache_bench.cpp).
#define STB_IMAGE_STATIC
#define STB_IMAGE_IMPLEMENTATION
#define STBI_ONLY_PNG
#include <stb_image.h>

#include <cstdio>
#include <cstring>
#include <string>

namespace texstream::render {

namespace fs = std::filesystem;

fs::path ReferenceFrames::frame_file(const fs::path& run_dir, uint64_t index) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%05llu.png", static_cast<unsigned long long>(index));
  return run_dir / "frames" / name;
}

Result<ReferenceFrames> ReferenceFrames::open(const fs::path& run_dir, uint32_t width, uint32_t height) {
  std::error_code ec;
  if (!fs::exists(frame_file(run_dir, 0), ec)) {
    return make_error(
        ErrorCode::kNotFound,
        "render.reference_dir '" + run_dir.string() + "': no " + frame_file(run_dir, 0).string() +
            " (render it with render.preload_all or render.load_wanted_before_drawing = true, write_every_frames = 1)");
  }
  ReferenceFrames r;
  r.dir_ = run_dir;
  r.width_ = width;
  r.height_ = height;
  return r;
}

Result<RgbaView> ReferenceFrames::frame(uint64_t index) {
  const fs::path file = frame_file(dir_, index);
  int w = 0, h = 0, n = 0;
  unsigned char* p = stbi_load(file.c_str(), &w, &h, &n, 4);
  if (!p) {
    return make_error(ErrorCode::kNotFound, "reference frame " + file.string() + ": " +
                                                (stbi_failure_reason() ? stbi_failure_reason() : "unreadable"));
  }
  if (static_cast<uint32_t>(w) != width_ || static_cast<uint32_t>(h) != height_) {
    stbi_image_free(p);
    return make_error(ErrorCode::kInvalidArgument, "reference frame " + file.string() + " is " + std::to_string(w) +
                                                       "x" + std::to_string(h) + ", the run renders " +
                                                       std::to_string(width_) + "x" + std::to_string(height_));
  }
  pixels_.resize(size_t{width_} * height_ * 4);
  std::memcpy(pixels_.data(), p, pixels_.size());
  stbi_image_free(p);
  return RgbaView{pixels_, width_, height_};
}

}  // namespace texstream::render
