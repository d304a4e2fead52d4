#pragma once
// Headless output: the colour target is copied into a host buffer in the frame's own command buffer and,
// after the frame's fence, written as an 8-bit RGBA PNG (the bytes are the sRGB-encoded attachment values).
#include <vulkan/vulkan.h>

#include <filesystem>
#include <span>

#include "texstream/common/result.hpp"
#include "texstream/render/vulkan/gpu_buffer.hpp"

namespace texstream::render {

class VulkanContext;

class FrameCapture {
 public:
  static Result<FrameCapture> create(const VulkanContext& ctx, uint32_t width, uint32_t height);
  // `image` is in TRANSFER_SRC_OPTIMAL (R8G8B8A8).
  void record(VkCommandBuffer cmd, VkImage image) const;
  // After the submission that ran record() has completed.
  Status write_png(const std::filesystem::path& file) const;
  // After the submission that ran record() has completed: width * height RGBA8 pixels, rows top to bottom.
  std::span<const std::byte> pixels() const { return buffer_.bytes(); }
  uint32_t width() const { return width_; }
  uint32_t height() const { return height_; }

 private:
  uint32_t width_ = 0;
  uint32_t height_ = 0;
  GpuBuffer buffer_;
};

}  // namespace texstream::render
