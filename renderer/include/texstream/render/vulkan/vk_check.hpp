#pragma once
// Every VkResult is checked: TS_VK_TRY turns a failed call into a Result error that names the call.
#include <vulkan/vulkan.h>

#include <string>

#include "texstream/common/result.hpp"

namespace texstream::render {

const char* vk_result_name(VkResult result);

inline Error vk_error(VkResult result, const std::string& what) {
  return make_error(ErrorCode::kVulkan, what + " failed: " + vk_result_name(result));
}

}  // namespace texstream::render

#define TS_VK_TRY(call)                                                                          \
  do {                                                                                           \
    const VkResult ts_vk_result_ = (call);                                                       \
    if (ts_vk_result_ != VK_SUCCESS) return ::texstream::render::vk_error(ts_vk_result_, #call); \
  } while (0)
