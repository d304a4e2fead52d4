#pragma once
// Start-up work that runs once and waits: record into a transient command buffer, submit, wait for the fence.
// Never on the frame path.
#include <vulkan/vulkan.h>

#include <functional>
#include <span>

#include "texstream/common/result.hpp"

namespace texstream::render {

class VulkanContext;
class GpuBuffer;

Status run_one_shot(const VulkanContext& ctx, const std::function<void(VkCommandBuffer)>& record);

// Copies `bytes` into `dst` at `offset` through a temporary host-visible buffer.
Status upload_to_buffer(const VulkanContext& ctx, const GpuBuffer& dst, VkDeviceSize offset,
                        std::span<const std::byte> bytes);

}  // namespace texstream::render
