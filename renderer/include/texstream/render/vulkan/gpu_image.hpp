#pragma once
// A VkImage with device-local memory and one view over all its mips and layers.
#include <vulkan/vulkan.h>

#include "texstream/common/result.hpp"
#include "texstream/render/vulkan/vk_handle.hpp"

namespace texstream::render {

class VulkanContext;

struct GpuImageInfo {
  VkFormat format = VK_FORMAT_R8G8B8A8_SRGB;
  uint32_t width = 1;
  uint32_t height = 1;
  uint32_t mip_levels = 1;
  uint32_t layers = 1;
  VkImageUsageFlags usage = 0;
  VkImageAspectFlags aspect = VK_IMAGE_ASPECT_COLOR_BIT;
  VkImageViewType view_type = VK_IMAGE_VIEW_TYPE_2D;
};

class GpuImage {
 public:
  static Result<GpuImage> create(const VulkanContext& ctx, const GpuImageInfo& info);
  GpuImage() = default;
  GpuImage(GpuImage&&) noexcept = default;
  GpuImage& operator=(GpuImage&&) noexcept = default;

  VkImage handle() const { return image_.get(); }
  VkImageView view() const { return view_.get(); }
  const GpuImageInfo& info() const { return info_; }

 private:
  GpuImageInfo info_;
  // Destroyed in reverse order: view, image, then its memory.
  UniqueMemory memory_;
  UniqueImage image_;
  UniqueImageView view_;
};

}  // namespace texstream::render
