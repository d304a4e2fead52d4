#pragma once
// The reference frames of a camera path (DESIGN "Determinism and measurement"): the frames a
// render.preload_all or render.load_wanted_before_drawing run wrote (render.write_every_frames = 1), read back
// one by one to measure a streamed run of the same path, frame size and frame time against them.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/render/measure/image_metrics.hpp"

namespace texstream::render {

class ReferenceFrames {
 public:
  // `run_dir` is the reference run's render.output_dir; its frames are <run_dir>/frames/frame_NNNNN.png.
  // Fails if the folder has no frame 0.
  static Result<ReferenceFrames> open(const std::filesystem::path& run_dir, uint32_t width, uint32_t height);
  // Frame `index`, decoded to RGBA8. Fails naming the file if it is missing, unreadable or of another size.
  Result<RgbaView> frame(uint64_t index);
  static std::filesystem::path frame_file(const std::filesystem::path& run_dir, uint64_t index);

 private:
  std::filesystem::path dir_;
  uint32_t width_ = 0, height_ = 0;
  std::vector<std::byte> pixels_;  // the last frame read
};

}  // namespace texstream::render
