#include "texstream/render/vulkan/one_shot.hpp"

#include <cstring>

#include "texstream/render/vulkan/gpu_buffer.hpp"
#include "texstream/render/vulkan/vk_check.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

namespace texstream::render {

Status run_one_shot(const VulkanContext& ctx, const std::function<void(VkCommandBuffer)>& record) {
  VkDevice device = ctx.device();
  VkCommandPoolCreateInfo pci{};
  pci.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
  pci.flags = VK_COMMAND_POOL_CREATE_TRANSIENT_BIT;
  pci.queueFamilyIndex = ctx.queue_family();
  VkCommandPool pool_handle = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateCommandPool(device, &pci, nullptr, &pool_handle));
  UniqueCommandPool pool(device, pool_handle);  // frees the command buffer with it

  VkCommandBufferAllocateInfo ai{};
  ai.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
  ai.commandPool = pool.get();
  ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  ai.commandBufferCount = 1;
  VkCommandBuffer cmd = VK_NULL_HANDLE;
  TS_VK_TRY(vkAllocateCommandBuffers(device, &ai, &cmd));
  VkCommandBufferBeginInfo bi{};
  bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
  bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  TS_VK_TRY(vkBeginCommandBuffer(cmd, &bi));
  record(cmd);
  TS_VK_TRY(vkEndCommandBuffer(cmd));

  VkFenceCreateInfo fci{};
  fci.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
  VkFence fence_handle = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateFence(device, &fci, nullptr, &fence_handle));
  UniqueFence fence(device, fence_handle);
  VkSubmitInfo si{};
  si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
  si.commandBufferCount = 1;
  si.pCommandBuffers = &cmd;
  TS_VK_TRY(vkQueueSubmit(ctx.queue(), 1, &si, fence.get()));
  TS_VK_TRY(vkWaitForFences(device, 1, &fence_handle, VK_TRUE, UINT64_MAX));
  return ok_status();
}

Status upload_to_buffer(const VulkanContext& ctx, const GpuBuffer& dst, VkDeviceSize offset,
                        std::span<const std::byte> bytes) {
  if (bytes.empty()) return ok_status();
  TS_ASSERT(offset + bytes.size() <= dst.size(), "upload past the end of the buffer");
  auto staging = GpuBuffer::create(ctx, bytes.size(), VK_BUFFER_USAGE_TRANSFER_SRC_BIT, MemoryUse::kHostVisible);
  if (!staging) return staging.error();
  std::memcpy(staging->bytes().data(), bytes.data(), bytes.size());
  return run_one_shot(ctx, [&](VkCommandBuffer cmd) {
    VkBufferCopy copy{0, offset, bytes.size()};
    vkCmdCopyBuffer(cmd, staging->handle(), dst.handle(), 1, &copy);
  });
}

}  // namespace texstream::render
