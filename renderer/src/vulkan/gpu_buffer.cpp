#include "texstream/render/vulkan/gpu_buffer.hpp"

#include <utility>

#include "texstream/render/vulkan/vk_check.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

namespace texstream::render {

Result<GpuBuffer> GpuBuffer::create(const VulkanContext& ctx, VkDeviceSize size, VkBufferUsageFlags usage,
                                    MemoryUse use) {
  TS_ASSERT(size > 0, "zero-sized buffer");
  VkDevice device = ctx.device();
  GpuBuffer b;
  b.size_ = size;
  VkBufferCreateInfo bci{};
  bci.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO;
  bci.size = size;
  bci.usage = usage;
  bci.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  VkBuffer buffer = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateBuffer(device, &bci, nullptr, &buffer));
  b.buffer_ = UniqueBuffer(device, buffer);

  VkMemoryRequirements req;
  vkGetBufferMemoryRequirements(device, buffer, &req);
  const bool host = use != MemoryUse::kDeviceLocal;
  const VkMemoryPropertyFlags preferred = use == MemoryUse::kHostRead ? VK_MEMORY_PROPERTY_HOST_CACHED_BIT : 0;
  auto mem =
      host ? ctx.allocate(req, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT, preferred)
           : ctx.allocate(req, 0, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  if (!mem) return mem.error();
  b.memory_ = std::move(*mem);
  VkDeviceMemory memory = b.memory_.get();
  TS_VK_TRY(vkBindBufferMemory(device, buffer, memory, 0));
  if (host) TS_VK_TRY(vkMapMemory(device, memory, 0, VK_WHOLE_SIZE, 0, &b.mapped_));
  return b;
}

GpuBuffer::~GpuBuffer() = default;  // freeing the memory unmaps it

std::span<std::byte> GpuBuffer::bytes() const {
  TS_ASSERT(mapped_ != nullptr, "bytes() of a buffer that is not host-visible");
  return {static_cast<std::byte*>(mapped_), static_cast<size_t>(size_)};
}

}  // namespace texstream::render
