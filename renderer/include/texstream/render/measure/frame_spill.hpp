#pragma once
// Captured frames parked on disk during a measured run and read back after it (render.reference_dir).
// Comparing a frame with its reference (PNG decode, SSIM) takes as long as drawing it at 640x360 on lavapipe;
// done at the frame, it would hand the server that much extra time per frame in real-time runs and flatter
// streaming. Appending the raw pixels costs a memcpy into the page cache instead; the comparison runs once
// the last frame is drawn. The file is removed when the spill is destroyed.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <span>
#include <vector>

#include "texstream/common/result.hpp"

namespace texstream::render {

class FrameSpill {
 public:
  static Result<FrameSpill> create(const std::filesystem::path& file, size_t frame_bytes);
  FrameSpill(FrameSpill&&) noexcept = default;
  FrameSpill& operator=(FrameSpill&&) noexcept = default;
  ~FrameSpill();

  // Contract: pixels.size() == frame_bytes.
  Status append(std::span<const std::byte> pixels);
  uint64_t frames() const { return frames_; }
  // Reads frame `index` (< frames()) into `out` (resized to frame_bytes).
  Status read(uint64_t index, std::vector<std::byte>& out);

 private:
  struct Closer {
    void operator()(std::FILE* f) const { std::fclose(f); }
  };
  FrameSpill() = default;
  std::filesystem::path file_;
  std::unique_ptr<std::FILE, Closer> f_;
  size_t frame_bytes_ = 0;
  uint64_t frames_ = 0;
};

}  // namespace texstream::render
