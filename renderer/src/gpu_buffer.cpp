#include "texstream/render/gpu_buffer.hpp"

#include "texstream/render/vk_check.hpp"
#include "texstream/render/vulkan_context.hpp"

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
  const bool host = use == MemoryUse::kHostVisible;
  auto type = host ? ctx.find_memory_type(req.memoryTypeBits,
                                          VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT, 0)
                   : ctx.find_memory_type(req.memoryTypeBits, 0, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  if (!type) return type.error();
  VkMemoryAllocateInfo mai{};
  mai.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
  mai.allocationSize = req.size;
  mai.memoryTypeIndex = *type;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  TS_VK_TRY(vkAllocateMemory(device, &mai, nullptr, &memory));
  b.memory_ = UniqueMemory(device, memory);
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
