#include "texstream/render/vulkan/vulkan_context.hpp"

#include <spdlog/spdlog.h>

#include <cstring>
#include <vector>

#include "texstream/render/vulkan/vk_check.hpp"

namespace texstream::render {

namespace {

constexpr const char* kValidationLayer = "VK_LAYER_KHRONOS_validation";

VKAPI_ATTR VkBool32 VKAPI_CALL debug_callback(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                              VkDebugUtilsMessageTypeFlagsEXT,
                                              const VkDebugUtilsMessengerCallbackDataEXT* data, void* user) {
  auto* counters = static_cast<ValidationCounters*>(user);
  const char* message = data && data->pMessage ? data->pMessage : "(no message)";
  if (severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT) {
    counters->errors.fetch_add(1, std::memory_order_relaxed);
    spdlog::error("vulkan validation: {}", message);
  } else if (severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT) {
    counters->warnings.fetch_add(1, std::memory_order_relaxed);
    spdlog::warn("vulkan validation: {}", message);
  }
  return VK_FALSE;  // never abort the call: we count and report
}

bool layer_available(const char* name) {
  uint32_t count = 0;
  if (vkEnumerateInstanceLayerProperties(&count, nullptr) != VK_SUCCESS) return false;
  std::vector<VkLayerProperties> layers(count);
  if (vkEnumerateInstanceLayerProperties(&count, layers.data()) != VK_SUCCESS) return false;
  for (const auto& l : layers)
    if (std::strcmp(l.layerName, name) == 0) return true;
  return false;
}

VkDebugUtilsMessengerCreateInfoEXT messenger_info(ValidationCounters* counters) {
  VkDebugUtilsMessengerCreateInfoEXT info{};
  info.sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT;
  info.messageSeverity =
      VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
  info.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                     VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
  info.pfnUserCallback = debug_callback;
  info.pUserData = counters;
  return info;
}

}  // namespace

Result<std::unique_ptr<VulkanContext>> VulkanContext::create(const VulkanContextOptions& options) {
  std::unique_ptr<VulkanContext> ctx(new VulkanContext());

  VkApplicationInfo app{};
  app.sType = VK_STRUCTURE_TYPE_APPLICATION_INFO;
  app.pApplicationName = "texstream-render";
  app.apiVersion = VK_API_VERSION_1_2;

  std::vector<const char*> layers;
  std::vector<const char*> extensions;
  if (options.validation) {
    if (!layer_available(kValidationLayer)) {
      return make_error(ErrorCode::kUnsupported,
                        "render.validation = true but the layer VK_LAYER_KHRONOS_validation is not installed");
    }
    layers.push_back(kValidationLayer);
    extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
  }
  for (const std::string& e : options.instance_extensions) extensions.push_back(e.c_str());
  VkInstanceCreateInfo ici{};
  ici.sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO;
  ici.pApplicationInfo = &app;
  ici.enabledLayerCount = static_cast<uint32_t>(layers.size());
  ici.ppEnabledLayerNames = layers.data();
  ici.enabledExtensionCount = static_cast<uint32_t>(extensions.size());
  ici.ppEnabledExtensionNames = extensions.data();
  // Chained so that instance creation and destruction are validated too.
  VkDebugUtilsMessengerCreateInfoEXT dbg = messenger_info(ctx->counters_.get());
  if (options.validation) ici.pNext = &dbg;
  TS_VK_TRY(vkCreateInstance(&ici, nullptr, &ctx->instance_));

  if (options.validation) {
    auto create_messenger = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(ctx->instance_, "vkCreateDebugUtilsMessengerEXT"));
    if (!create_messenger) return make_error(ErrorCode::kUnsupported, "vkCreateDebugUtilsMessengerEXT not found");
    TS_VK_TRY(create_messenger(ctx->instance_, &dbg, nullptr, &ctx->messenger_));
  }

  uint32_t count = 0;
  TS_VK_TRY(vkEnumeratePhysicalDevices(ctx->instance_, &count, nullptr));
  std::vector<VkPhysicalDevice> devices(count);
  TS_VK_TRY(vkEnumeratePhysicalDevices(ctx->instance_, &count, devices.data()));
  std::string names;
  for (VkPhysicalDevice pd : devices) {
    VkPhysicalDeviceProperties props;
    vkGetPhysicalDeviceProperties(pd, &props);
    names += std::string(names.empty() ? "" : ", ") + "'" + props.deviceName + "'";
    if (!ctx->physical_ && (options.device_substring.empty() ||
                            std::strstr(props.deviceName, options.device_substring.c_str()) != nullptr)) {
      ctx->physical_ = pd;
      ctx->properties_ = props;
    }
  }
  if (!ctx->physical_) {
    return make_error(ErrorCode::kNotFound, "render.device: no Vulkan device name contains '" +
                                                options.device_substring +
                                                "' (devices: " + (names.empty() ? "none" : names) + ")");
  }
  if (ctx->properties_.apiVersion < VK_API_VERSION_1_2) {
    return make_error(ErrorCode::kUnsupported,
                      std::string("device '") + ctx->properties_.deviceName + "' supports only Vulkan < 1.2");
  }
  vkGetPhysicalDeviceMemoryProperties(ctx->physical_, &ctx->memory_properties_);
  {
    // Subgroup reductions let the visibility metadata do one atomic pair per (subgroup, mesh) instead of one per
    // pixel (meta_reduce.comp, the wide pass's scene.frag): core in Vulkan 1.1, but which stages and operations
    // is the device's choice.
    VkPhysicalDeviceSubgroupProperties subgroup{};
    subgroup.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SUBGROUP_PROPERTIES;
    VkPhysicalDeviceProperties2 props2{};
    props2.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2;
    props2.pNext = &subgroup;
    vkGetPhysicalDeviceProperties2(ctx->physical_, &props2);
    const VkSubgroupFeatureFlags needed =
        VK_SUBGROUP_FEATURE_BASIC_BIT | VK_SUBGROUP_FEATURE_ARITHMETIC_BIT | VK_SUBGROUP_FEATURE_BALLOT_BIT;
    ctx->subgroup_reduce_stages_ = (subgroup.supportedOperations & needed) == needed ? subgroup.supportedStages : 0;
  }

  uint32_t family_count = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(ctx->physical_, &family_count, nullptr);
  std::vector<VkQueueFamilyProperties> families(family_count);
  vkGetPhysicalDeviceQueueFamilyProperties(ctx->physical_, &family_count, families.data());
  bool found = false;
  // The texture cache binds its sparse pages on this queue (one queue: binds, copies and draws stay in one
  // timeline), so prefer a family that also has VK_QUEUE_SPARSE_BINDING_BIT; TextureCache names the problem if
  // the chosen one lacks it.
  for (const bool need_sparse : {true, false}) {
    for (uint32_t i = 0; i < family_count && !found; ++i) {
      if ((families[i].queueFlags & VK_QUEUE_GRAPHICS_BIT) && (families[i].queueFlags & VK_QUEUE_COMPUTE_BIT) &&
          (!need_sparse || (families[i].queueFlags & VK_QUEUE_SPARSE_BINDING_BIT)) &&
          (!options.can_present || options.can_present(ctx->instance_, ctx->physical_, i))) {
        ctx->queue_family_ = i;
        found = true;
      }
    }
    if (found) break;
  }
  if (!found) {
    return make_error(ErrorCode::kUnsupported, options.can_present
                                                   ? "no graphics+compute queue family that can present to the window"
                                                   : "no graphics+compute queue family on the device");
  }

  VkPhysicalDeviceFeatures supported{};
  vkGetPhysicalDeviceFeatures(ctx->physical_, &supported);
  VkPhysicalDeviceFeatures features{};
  // Multi-draw indirect over runs of meshes; firstInstance carries an instanced mesh's id (SceneGpu).
  if (!supported.multiDrawIndirect || !supported.drawIndirectFirstInstance)
    return make_error(ErrorCode::kUnsupported, "device lacks multiDrawIndirect / drawIndirectFirstInstance");
  features.multiDrawIndirect = VK_TRUE;
  features.drawIndirectFirstInstance = VK_TRUE;
  // Visibility metadata atomics in the fragment shader (seed 000 §3.2).
  if (!supported.fragmentStoresAndAtomics)
    return make_error(ErrorCode::kUnsupported, "device lacks fragmentStoresAndAtomics");
  features.fragmentStoresAndAtomics = VK_TRUE;
  // Only the LOD probe (tests, benchmark) samples anisotropically; without the feature it reports isotropic.
  if (supported.samplerAnisotropy) {
    features.samplerAnisotropy = VK_TRUE;
    ctx->sampler_anisotropy_ = true;
  }
  // The texture cache is a sparse partially-resident image (seed 000 §3.6); SparseMemory::create reports a
  // device without these features.
  features.sparseBinding = supported.sparseBinding;
  features.sparseResidencyImage2D = supported.sparseResidencyImage2D;
  if (options.need_bc && !supported.textureCompressionBC)
    return make_error(ErrorCode::kUnsupported, "cache.format = bc1/bc3/bc7 but the device lacks textureCompressionBC");
  // On wherever the device has it: a scene's records may name BC formats its scene.json does not.
  features.textureCompressionBC = supported.textureCompressionBC;
  ctx->texture_compression_bc_ = supported.textureCompressionBC == VK_TRUE;

  const float priority = 1.0f;
  VkDeviceQueueCreateInfo qci{};
  qci.sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO;
  qci.queueFamilyIndex = ctx->queue_family_;
  qci.queueCount = 1;
  qci.pQueuePriorities = &priority;
  VkDeviceCreateInfo dci{};
  dci.sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO;
  dci.queueCreateInfoCount = 1;
  dci.pQueueCreateInfos = &qci;
  dci.pEnabledFeatures = &features;
  // Vulkan 1.2 core: the cache's sparse binds signal a timeline semaphore that the frame's submission waits on.
  VkPhysicalDeviceVulkan12Features supported12{};
  supported12.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES;
  VkPhysicalDeviceFeatures2 supported2{};
  supported2.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2;
  supported2.pNext = &supported12;
  vkGetPhysicalDeviceFeatures2(ctx->physical_, &supported2);
  if (!supported12.timelineSemaphore) return make_error(ErrorCode::kUnsupported, "device lacks timelineSemaphore");
  VkPhysicalDeviceVulkan12Features features12{};
  features12.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES;
  features12.timelineSemaphore = VK_TRUE;
  // Core and 1.2 features in one chain (pEnabledFeatures must then be null).
  VkPhysicalDeviceFeatures2 features2{};
  features2.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2;
  features2.features = features;
  features2.pNext = &features12;
  dci.pEnabledFeatures = nullptr;
  dci.pNext = &features2;
  const char* swapchain_ext = VK_KHR_SWAPCHAIN_EXTENSION_NAME;
  if (options.can_present) {
    dci.enabledExtensionCount = 1;
    dci.ppEnabledExtensionNames = &swapchain_ext;
  }
  TS_VK_TRY(vkCreateDevice(ctx->physical_, &dci, nullptr, &ctx->device_));
  vkGetDeviceQueue(ctx->device_, ctx->queue_family_, 0, &ctx->queue_);
  return ctx;
}

VulkanContext::~VulkanContext() {
  if (device_) {
    vkDeviceWaitIdle(device_);  // nothing we could do about a failure while tearing down
    vkDestroyDevice(device_, nullptr);
  }
  if (messenger_) {
    auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance_, "vkDestroyDebugUtilsMessengerEXT"));
    if (destroy) destroy(instance_, messenger_, nullptr);
  }
  if (instance_) vkDestroyInstance(instance_, nullptr);
}

Result<uint32_t> VulkanContext::find_memory_type(uint32_t type_bits, VkMemoryPropertyFlags required,
                                                 VkMemoryPropertyFlags preferred) const {
  int fallback = -1;
  for (uint32_t i = 0; i < memory_properties_.memoryTypeCount; ++i) {
    if (!(type_bits & (1u << i))) continue;
    const VkMemoryPropertyFlags flags = memory_properties_.memoryTypes[i].propertyFlags;
    if ((flags & required) != required) continue;
    if ((flags & preferred) == preferred) return i;
    if (fallback < 0) fallback = static_cast<int>(i);
  }
  if (fallback >= 0) return static_cast<uint32_t>(fallback);
  return make_error(ErrorCode::kUnsupported, "no Vulkan memory type with the required properties");
}

Result<UniqueMemory> VulkanContext::allocate(const VkMemoryRequirements& req, VkMemoryPropertyFlags required,
                                             VkMemoryPropertyFlags preferred) const {
  auto type = find_memory_type(req.memoryTypeBits, required, preferred);
  if (!type) return type.error();
  VkMemoryAllocateInfo mai{};
  mai.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
  mai.allocationSize = req.size;
  mai.memoryTypeIndex = *type;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  TS_VK_TRY(vkAllocateMemory(device_, &mai, nullptr, &memory));
  return UniqueMemory(device_, memory);
}

}  // namespace texstream::render
