#include "texstream/render/window/swapchain_presenter.hpp"

#include <algorithm>
#include <array>

#include "texstream/render/vulkan/image_barrier.hpp"
#include "texstream/render/vulkan/vk_check.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"
#include "texstream/render/window/app_window.hpp"

namespace texstream::render {

Result<std::unique_ptr<SwapchainPresenter>> SwapchainPresenter::create(const VulkanContext& ctx,
                                                                       const AppWindow& window, VkSurfaceKHR surface) {
  std::unique_ptr<SwapchainPresenter> p(new SwapchainPresenter(ctx, window));
  p->surface_ = surface;
  VkBool32 supported = VK_FALSE;
  TS_VK_TRY(vkGetPhysicalDeviceSurfaceSupportKHR(ctx.physical_device(), ctx.queue_family(), surface, &supported));
  if (!supported) return make_error(ErrorCode::kUnsupported, "the renderer's queue cannot present to the window");
  VkDevice device = ctx.device();
  VkCommandPoolCreateInfo pci{};
  pci.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
  pci.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pci.queueFamilyIndex = ctx.queue_family();
  VkCommandPool pool = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateCommandPool(device, &pci, nullptr, &pool));
  p->pool_ = UniqueCommandPool(device, pool);
  VkCommandBufferAllocateInfo ai{};
  ai.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
  ai.commandPool = pool;
  ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  ai.commandBufferCount = 1;
  TS_VK_TRY(vkAllocateCommandBuffers(device, &ai, &p->cmd_));
  VkSemaphoreCreateInfo sci{};
  sci.sType = VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO;
  VkSemaphore a = VK_NULL_HANDLE, b = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateSemaphore(device, &sci, nullptr, &a));
  p->acquired_ = UniqueSemaphore(device, a);
  TS_VK_TRY(vkCreateSemaphore(device, &sci, nullptr, &b));
  p->blitted_ = UniqueSemaphore(device, b);
  VkFenceCreateInfo fci{};
  fci.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
  VkFence fence = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateFence(device, &fci, nullptr, &fence));
  p->fence_ = UniqueFence(device, fence);
  TS_TRY(p->rebuild());
  return p;
}

SwapchainPresenter::~SwapchainPresenter() {
  if (ctx_.device()) vkDeviceWaitIdle(ctx_.device());  // nothing to do about a failure while tearing down
  swapchain_.reset();
  if (surface_) vkDestroySurfaceKHR(ctx_.instance(), surface_, nullptr);
}

Status SwapchainPresenter::rebuild() {
  VkPhysicalDevice pd = ctx_.physical_device();
  VkSurfaceCapabilitiesKHR caps{};
  TS_VK_TRY(vkGetPhysicalDeviceSurfaceCapabilitiesKHR(pd, surface_, &caps));
  uint32_t w = 0, h = 0;
  window_.framebuffer_size(w, h);
  if (caps.currentExtent.width != 0xFFFFFFFFu) {
    extent_ = caps.currentExtent;
  } else {
    extent_ = {std::clamp(w, caps.minImageExtent.width, caps.maxImageExtent.width),
               std::clamp(h, caps.minImageExtent.height, caps.maxImageExtent.height)};
  }
  stale_ = false;
  if (extent_.width == 0 || extent_.height == 0) return ok_status();  // minimised: nothing to present into
  if (!(caps.supportedUsageFlags & VK_IMAGE_USAGE_TRANSFER_DST_BIT)) {
    return make_error(ErrorCode::kUnsupported, "the window's swapchain images cannot be blitted into");
  }
  uint32_t count = 0;
  TS_VK_TRY(vkGetPhysicalDeviceSurfaceFormatsKHR(pd, surface_, &count, nullptr));
  std::vector<VkSurfaceFormatKHR> formats(count);
  TS_VK_TRY(vkGetPhysicalDeviceSurfaceFormatsKHR(pd, surface_, &count, formats.data()));
  if (formats.empty()) return make_error(ErrorCode::kUnsupported, "the window surface offers no format");
  // An sRGB swapchain keeps the blit a plain copy of the sRGB-encoded frame; any other format still works
  // (the blit converts), only less exactly.
  VkSurfaceFormatKHR format = formats[0];
  for (const auto& f : formats)
    if ((f.format == VK_FORMAT_B8G8R8A8_SRGB || f.format == VK_FORMAT_R8G8B8A8_SRGB) &&
        f.colorSpace == VK_COLOR_SPACE_SRGB_NONLINEAR_KHR)
      format = f;

  VkSwapchainCreateInfoKHR ci{};
  ci.sType = VK_STRUCTURE_TYPE_SWAPCHAIN_CREATE_INFO_KHR;
  ci.surface = surface_;
  ci.minImageCount = std::max(caps.minImageCount, 2u);
  if (caps.maxImageCount > 0) ci.minImageCount = std::min(ci.minImageCount, caps.maxImageCount);
  ci.imageFormat = format.format;
  ci.imageColorSpace = format.colorSpace;
  ci.imageExtent = extent_;
  ci.imageArrayLayers = 1;
  ci.imageUsage = VK_IMAGE_USAGE_TRANSFER_DST_BIT;
  ci.imageSharingMode = VK_SHARING_MODE_EXCLUSIVE;
  ci.preTransform = caps.currentTransform;
  ci.compositeAlpha =
      (caps.supportedCompositeAlpha & VK_COMPOSITE_ALPHA_OPAQUE_BIT_KHR)
          ? VK_COMPOSITE_ALPHA_OPAQUE_BIT_KHR
          : static_cast<VkCompositeAlphaFlagBitsKHR>(caps.supportedCompositeAlpha & -caps.supportedCompositeAlpha);
  ci.presentMode = VK_PRESENT_MODE_FIFO_KHR;  // the one mode every surface has
  ci.clipped = VK_TRUE;
  ci.oldSwapchain = swapchain_.get();
  VkSwapchainKHR sc = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateSwapchainKHR(ctx_.device(), &ci, nullptr, &sc));
  swapchain_ = UniqueSwapchain(ctx_.device(), sc);  // destroys the old one (idle: every present waited)
  TS_VK_TRY(vkGetSwapchainImagesKHR(ctx_.device(), sc, &count, nullptr));
  images_.resize(count);
  TS_VK_TRY(vkGetSwapchainImagesKHR(ctx_.device(), sc, &count, images_.data()));
  return ok_status();
}

Status SwapchainPresenter::present(VkImage image, uint32_t width, uint32_t height) {
  if (stale_) {
    TS_VK_TRY(vkDeviceWaitIdle(ctx_.device()));
    TS_TRY(rebuild());
  }
  if (!swapchain_ || extent_.width == 0 || extent_.height == 0) {
    stale_ = true;  // minimised: look again next frame
    return ok_status();
  }
  VkDevice device = ctx_.device();
  uint32_t index = 0;
  VkResult r = vkAcquireNextImageKHR(device, swapchain_.get(), UINT64_MAX, acquired_.get(), VK_NULL_HANDLE, &index);
  if (r == VK_ERROR_OUT_OF_DATE_KHR) {
    stale_ = true;
    return ok_status();
  }
  if (r != VK_SUCCESS && r != VK_SUBOPTIMAL_KHR) TS_VK_TRY(r);

  TS_VK_TRY(vkResetCommandBuffer(cmd_, 0));
  VkCommandBufferBeginInfo bi{};
  bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
  bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  TS_VK_TRY(vkBeginCommandBuffer(cmd_, &bi));
  VkImage target = images_[index];
  image_barrier(cmd_, target, VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 0,
                VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT);
  VkImageBlit blit{};
  blit.srcSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  blit.srcOffsets[1] = {static_cast<int32_t>(width), static_cast<int32_t>(height), 1};
  blit.dstSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  blit.dstOffsets[1] = {static_cast<int32_t>(extent_.width), static_cast<int32_t>(extent_.height), 1};
  vkCmdBlitImage(cmd_, image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, target, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1,
                 &blit, VK_FILTER_LINEAR);
  image_barrier(cmd_, target, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_IMAGE_LAYOUT_PRESENT_SRC_KHR,
                VK_ACCESS_TRANSFER_WRITE_BIT, 0, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT);
  TS_VK_TRY(vkEndCommandBuffer(cmd_));

  const VkPipelineStageFlags wait_stage = VK_PIPELINE_STAGE_TRANSFER_BIT;
  VkSemaphore acquired = acquired_.get();
  VkSemaphore blitted = blitted_.get();
  VkSubmitInfo si{};
  si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
  si.waitSemaphoreCount = 1;
  si.pWaitSemaphores = &acquired;
  si.pWaitDstStageMask = &wait_stage;
  si.commandBufferCount = 1;
  si.pCommandBuffers = &cmd_;
  si.signalSemaphoreCount = 1;
  si.pSignalSemaphores = &blitted;
  VkFence fence = fence_.get();
  TS_VK_TRY(vkResetFences(device, 1, &fence));
  TS_VK_TRY(vkQueueSubmit(ctx_.queue(), 1, &si, fence));

  VkSwapchainKHR sc = swapchain_.get();
  VkPresentInfoKHR pi{};
  pi.sType = VK_STRUCTURE_TYPE_PRESENT_INFO_KHR;
  pi.waitSemaphoreCount = 1;
  pi.pWaitSemaphores = &blitted;
  pi.swapchainCount = 1;
  pi.pSwapchains = &sc;
  pi.pImageIndices = &index;
  r = vkQueuePresentKHR(ctx_.queue(), &pi);
  // The blit must finish before the next frame's render pass overwrites the colour target.
  TS_VK_TRY(vkWaitForFences(device, 1, &fence, VK_TRUE, UINT64_MAX));
  if (r == VK_ERROR_OUT_OF_DATE_KHR || r == VK_SUBOPTIMAL_KHR) {
    stale_ = true;
  } else {
    TS_VK_TRY(r);
  }
  ++presented_;
  return ok_status();
}

}  // namespace texstream::render
