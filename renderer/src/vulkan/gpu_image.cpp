#include "texstream/render/vulkan/gpu_image.hpp"

#include <utility>

#include "texstream/render/vulkan/vk_check.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

namespace texstream::render {

Result<GpuImage> GpuImage::create(const VulkanContext& ctx, const GpuImageInfo& info) {
  VkDevice device = ctx.device();
  GpuImage img;
  img.info_ = info;
  VkImageCreateInfo ici{};
  ici.sType = VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO;
  ici.imageType = VK_IMAGE_TYPE_2D;
  ici.format = info.format;
  ici.extent = {info.width, info.height, 1};
  ici.mipLevels = info.mip_levels;
  ici.arrayLayers = info.layers;
  ici.samples = VK_SAMPLE_COUNT_1_BIT;
  ici.tiling = VK_IMAGE_TILING_OPTIMAL;
  ici.usage = info.usage;
  ici.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  ici.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  VkImage image = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateImage(device, &ici, nullptr, &image));
  img.image_ = UniqueImage(device, image);

  VkMemoryRequirements req;
  vkGetImageMemoryRequirements(device, image, &req);
  auto mem = ctx.allocate(req, 0, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  if (!mem) return mem.error();
  img.memory_ = std::move(*mem);
  VkDeviceMemory memory = img.memory_.get();
  TS_VK_TRY(vkBindImageMemory(device, image, memory, 0));

  VkImageViewCreateInfo vci{};
  vci.sType = VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO;
  vci.image = image;
  vci.viewType = info.view_type;
  vci.format = info.format;
  vci.subresourceRange = {info.aspect, 0, info.mip_levels, 0, info.layers};
  VkImageView view = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateImageView(device, &vci, nullptr, &view));
  img.view_ = UniqueImageView(device, view);
  return img;
}

}  // namespace texstream::render
