#pragma once
// Instance, optional validation layer with a counting debug messenger, physical device chosen by name
// substring (lavapipe "llvmpipe" by default), logical device and one graphics+compute+transfer queue.
#include <vulkan/vulkan.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/render/vulkan/vk_handle.hpp"

namespace texstream::render {

struct VulkanContextOptions {
  std::string device_substring;  // empty: the first device
  bool validation = false;       // VK_LAYER_KHRONOS_validation + debug messenger
  bool need_bc = false;          // textureCompressionBC (cache.format = bc1, bc3 or bc7)
  // Window mode: instance extensions the window system needs (glfwGetRequiredInstanceExtensions), and a test
  // that the queue family can present (glfwGetPhysicalDevicePresentationSupport); non-empty adds
  // VK_KHR_swapchain to the device.
  std::vector<std::string> instance_extensions;
  std::function<bool(VkInstance, VkPhysicalDevice, uint32_t)> can_present;
};

// Counts of validation messages; the messenger callback may run on any thread.
struct ValidationCounters {
  std::atomic<uint32_t> errors{0};
  std::atomic<uint32_t> warnings{0};
};

class VulkanContext {
 public:
  static Result<std::unique_ptr<VulkanContext>> create(const VulkanContextOptions& options);
  ~VulkanContext();
  VulkanContext(const VulkanContext&) = delete;
  VulkanContext& operator=(const VulkanContext&) = delete;

  VkInstance instance() const { return instance_; }
  VkPhysicalDevice physical_device() const { return physical_; }
  VkDevice device() const { return device_; }
  VkQueue queue() const { return queue_; }
  uint32_t queue_family() const { return queue_family_; }
  const VkPhysicalDeviceProperties& properties() const { return properties_; }
  std::string device_name() const { return properties_.deviceName; }
  // samplerAnisotropy is enabled (the LOD probe's sampler uses it when the device has it).
  bool sampler_anisotropy() const { return sampler_anisotropy_; }
  bool texture_compression_bc() const { return texture_compression_bc_; }
  // Whether shaders of `stage` have basic, arithmetic and ballot subgroup operations (Vulkan 1.1 leaves both
  // the stages and the operations to the device).
  bool subgroup_reductions(VkShaderStageFlagBits stage) const { return (subgroup_reduce_stages_ & stage) != 0; }

  uint32_t validation_errors() const { return counters_->errors.load(std::memory_order_relaxed); }
  uint32_t validation_warnings() const { return counters_->warnings.load(std::memory_order_relaxed); }

  // A memory type index among `type_bits` that has all of `required`; prefers one that also has `preferred`.
  Result<uint32_t> find_memory_type(uint32_t type_bits, VkMemoryPropertyFlags required,
                                    VkMemoryPropertyFlags preferred) const;
  // One dedicated allocation for `req` in such a memory type (buffers and images that own their memory).
  Result<UniqueMemory> allocate(const VkMemoryRequirements& req, VkMemoryPropertyFlags required,
                                VkMemoryPropertyFlags preferred) const;

 private:
  VulkanContext() = default;
  VkInstance instance_ = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger_ = VK_NULL_HANDLE;
  VkPhysicalDevice physical_ = VK_NULL_HANDLE;
  VkDevice device_ = VK_NULL_HANDLE;
  VkQueue queue_ = VK_NULL_HANDLE;
  uint32_t queue_family_ = 0;
  bool sampler_anisotropy_ = false;
  bool texture_compression_bc_ = false;
  VkShaderStageFlags subgroup_reduce_stages_ = 0;
  VkPhysicalDeviceProperties properties_{};
  VkPhysicalDeviceMemoryProperties memory_properties_{};
  std::unique_ptr<ValidationCounters> counters_ = std::make_unique<ValidationCounters>();
};

}  // namespace texstream::render
