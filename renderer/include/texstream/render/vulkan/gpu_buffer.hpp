#pragma once
// A VkBuffer with its own memory. Host-visible buffers are coherent and stay mapped for their lifetime.
#include <vulkan/vulkan.h>

#include <cstddef>
#include <span>

#include "texstream/common/result.hpp"
#include "texstream/render/vulkan/vk_handle.hpp"

namespace texstream::render {

class VulkanContext;

enum class MemoryUse {
  kDeviceLocal,  // GPU only; filled by copies
  kHostVisible,  // CPU writes it every frame (host-coherent, persistently mapped)
  kHostRead,     // GPU writes, CPU reads (host-coherent, mapped, host-cached where the device has such memory:
                 // reading uncached write-combined memory costs ~100 us per 10 KB on a discrete GPU)
};

class GpuBuffer {
 public:
  static Result<GpuBuffer> create(const VulkanContext& ctx, VkDeviceSize size, VkBufferUsageFlags usage, MemoryUse use);
  GpuBuffer() = default;
  GpuBuffer(GpuBuffer&&) noexcept = default;
  GpuBuffer& operator=(GpuBuffer&&) noexcept = default;
  ~GpuBuffer();

  VkBuffer handle() const { return buffer_.get(); }
  VkDeviceSize size() const { return size_; }
  // Host-visible only (asserted): the whole buffer as bytes.
  std::span<std::byte> bytes() const;
  template <class T>
  T* as() const {
    return reinterpret_cast<T*>(bytes().data());
  }

 private:
  UniqueMemory memory_;  // declared first: destroyed after the buffer bound to it
  UniqueBuffer buffer_;
  VkDeviceSize size_ = 0;
  void* mapped_ = nullptr;
};

}  // namespace texstream::render
