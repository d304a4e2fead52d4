#pragma once
// Shows the renderer's colour target in the window: acquire a swapchain image, blit the frame into it (any
// size and format conversion is the blit's), present. Its own command buffer, semaphores and fence, submitted
// after the frame's fence, so the headless frame path stays exactly as it is. An out-of-date swapchain (the
// window changed) is rebuilt at the next frame; a minimised window skips presenting.
#include <vulkan/vulkan.h>

#include <memory>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/render/vulkan/vk_handle.hpp"

namespace texstream::render {

class VulkanContext;
class AppWindow;

class SwapchainPresenter {
 public:
  // Takes ownership of `surface` (destroyed with the presenter, before the instance).
  static Result<std::unique_ptr<SwapchainPresenter>> create(const VulkanContext& ctx, const AppWindow& window,
                                                            VkSurfaceKHR surface);
  ~SwapchainPresenter();
  SwapchainPresenter(const SwapchainPresenter&) = delete;
  SwapchainPresenter& operator=(const SwapchainPresenter&) = delete;

  // `image` (width x height) is in TRANSFER_SRC_OPTIMAL and stays so; the frame that wrote it has completed.
  Status present(VkImage image, uint32_t width, uint32_t height);
  uint64_t presented() const { return presented_; }

 private:
  SwapchainPresenter(const VulkanContext& ctx, const AppWindow& window) : ctx_(ctx), window_(window) {}
  Status rebuild();

  const VulkanContext& ctx_;
  const AppWindow& window_;
  VkSurfaceKHR surface_ = VK_NULL_HANDLE;
  UniqueSwapchain swapchain_;
  std::vector<VkImage> images_;
  VkExtent2D extent_{};
  UniqueCommandPool pool_;
  VkCommandBuffer cmd_ = VK_NULL_HANDLE;
  UniqueSemaphore acquired_;
  UniqueSemaphore blitted_;
  UniqueFence fence_;
  bool stale_ = false;  // rebuild before the next acquire
  uint64_t presented_ = 0;
};

}  // namespace texstream::render
