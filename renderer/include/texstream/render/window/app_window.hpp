#pragma once
// The GLFW window of the interactive mode (render.window = true): no client API (Vulkan draws into it through
// a swapchain), keyboard and mouse turned into FlyInput, and key edges (R: record the camera, Esc: close).
// Works under Xvfb. Main thread only (GLFW's rule).
#include <vulkan/vulkan.h>

#include <memory>
#include <string>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/render/window/fly_camera.hpp"

struct GLFWwindow;

namespace texstream::render {

struct WindowEvents {
  FlyInput fly;
  bool toggle_recording = false;  // R was pressed since the last poll
};

class AppWindow {
 public:
  static Result<std::unique_ptr<AppWindow>> open(uint32_t width, uint32_t height, const std::string& title);
  ~AppWindow();
  AppWindow(const AppWindow&) = delete;
  AppWindow& operator=(const AppWindow&) = delete;

  // What VulkanContext needs: the instance extensions of the window system, and a presentation test.
  static std::vector<std::string> required_instance_extensions();
  static bool can_present(VkInstance instance, VkPhysicalDevice device, uint32_t queue_family);

  Result<VkSurfaceKHR> create_surface(VkInstance instance) const;
  // Processes pending events and returns this frame's input.
  WindowEvents poll();
  bool should_close() const;
  void set_title(const std::string& title);
  // Current framebuffer size in pixels (0 x 0 while minimised).
  void framebuffer_size(uint32_t& width, uint32_t& height) const;

 private:
  AppWindow() = default;
  GLFWwindow* window_ = nullptr;
  bool r_was_down_ = false;
  bool have_cursor_ = false;
  double last_x_ = 0, last_y_ = 0;
};

}  // namespace texstream::render
