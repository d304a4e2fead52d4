#pragma once
// Image error of every frame of a run against the frames of a reference run (render.reference_dir, DESIGN
// "Determinism and measurement"): MSE, PSNR, SSIM per frame, and pop-in (the MSE between two consecutive
// frames while the camera is still: then every change is refinement, seed 000 Fig. 7).
//
// At the frame only the captured pixels are appended to a spill file (FrameSpill: a copy into the page
// cache); the comparison runs in measure(), after the last frame, so it never gives the server extra time
// between frames of a real-time run.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/render/measure/frame_log.hpp"
#include "texstream/render/measure/frame_spill.hpp"
#include "texstream/render/measure/reference_frames.hpp"

namespace texstream::render {

class FrameMeasurement {
 public:
  // `reference_dir`: the reference run's output folder (its frames/frame_NNNNN.png, width x height). The
  // spill file lives in `output_dir` until measure().
  static Result<std::unique_ptr<FrameMeasurement>> open(const std::filesystem::path& reference_dir,
                                                        const std::filesystem::path& output_dir, uint32_t width,
                                                        uint32_t height);
  // The frame's RGBA8 pixels (width * height * 4 bytes), in frame order.
  Status add(std::span<const std::byte> pixels);
  // Fills mse, psnr_db, ssim and popin_mse of frames[i] from the i-th added frame (frames[i].camera_still
  // says whether pop-in applies). Fails naming the reference file that is missing or of another size.
  Status measure(std::vector<FrameRecord>& frames);

 private:
  FrameMeasurement(ReferenceFrames reference, FrameSpill spill, uint32_t width, uint32_t height)
      : reference_(std::move(reference)), spill_(std::move(spill)), width_(width), height_(height) {}
  ReferenceFrames reference_;
  FrameSpill spill_;
  uint32_t width_, height_;
};

}  // namespace texstream::render
