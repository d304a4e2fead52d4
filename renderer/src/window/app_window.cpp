#include "texstream/render/window/app_window.hpp"

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

namespace texstream::render {

namespace {

std::string glfw_error() {
  const char* text = nullptr;
  glfwGetError(&text);
  return text ? text : "unknown GLFW error";
}

}  // namespace

Result<std::unique_ptr<AppWindow>> AppWindow::open(uint32_t width, uint32_t height, const std::string& title) {
  if (!glfwInit()) {
    return make_error(ErrorCode::kUnsupported, "render.window = true: cannot open the window system (" + glfw_error() +
                                                   "); is DISPLAY set? (xvfb-run provides one)");
  }
  if (!glfwVulkanSupported()) {
    glfwTerminate();
    return make_error(ErrorCode::kUnsupported, "render.window = true: GLFW finds no Vulkan loader");
  }
  glfwWindowHint(GLFW_CLIENT_API, GLFW_NO_API);
  glfwWindowHint(GLFW_RESIZABLE, GLFW_FALSE);  // the off-screen targets have the configured size
  std::unique_ptr<AppWindow> w(new AppWindow());
  w->window_ = glfwCreateWindow(static_cast<int>(width), static_cast<int>(height), title.c_str(), nullptr, nullptr);
  if (!w->window_) {
    const std::string why = glfw_error();
    glfwTerminate();
    return make_error(ErrorCode::kUnsupported, "render.window = true: cannot create the window (" + why + ")");
  }
  return w;
}

AppWindow::~AppWindow() {
  if (window_) glfwDestroyWindow(window_);
  glfwTerminate();
}

std::vector<std::string> AppWindow::required_instance_extensions() {
  uint32_t count = 0;
  const char** names = glfwGetRequiredInstanceExtensions(&count);
  std::vector<std::string> out;
  for (uint32_t i = 0; names && i < count; ++i) out.emplace_back(names[i]);
  return out;
}

bool AppWindow::can_present(VkInstance instance, VkPhysicalDevice device, uint32_t queue_family) {
  return glfwGetPhysicalDevicePresentationSupport(instance, device, queue_family) == GLFW_TRUE;
}

Result<VkSurfaceKHR> AppWindow::create_surface(VkInstance instance) const {
  VkSurfaceKHR surface = VK_NULL_HANDLE;
  const VkResult r = glfwCreateWindowSurface(instance, window_, nullptr, &surface);
  if (r != VK_SUCCESS) {
    return make_error(ErrorCode::kVulkan, "glfwCreateWindowSurface failed (VkResult " + std::to_string(r) + ")");
  }
  return surface;
}

WindowEvents AppWindow::poll() {
  glfwPollEvents();
  WindowEvents e;
  auto down = [&](int key) { return glfwGetKey(window_, key) == GLFW_PRESS; };
  e.fly.forward = down(GLFW_KEY_W);
  e.fly.back = down(GLFW_KEY_S);
  e.fly.left = down(GLFW_KEY_A);
  e.fly.right = down(GLFW_KEY_D);
  e.fly.up = down(GLFW_KEY_E) || down(GLFW_KEY_SPACE);
  e.fly.down = down(GLFW_KEY_Q) || down(GLFW_KEY_C);
  e.fly.fast = down(GLFW_KEY_LEFT_SHIFT) || down(GLFW_KEY_RIGHT_SHIFT);
  const bool r = down(GLFW_KEY_R);
  e.toggle_recording = r && !r_was_down_;
  r_was_down_ = r;
  if (down(GLFW_KEY_ESCAPE)) glfwSetWindowShouldClose(window_, GLFW_TRUE);
  // Mouse look while the left button is held: the cursor stays free for the rest of the desktop.
  double x = 0, y = 0;
  glfwGetCursorPos(window_, &x, &y);
  if (glfwGetMouseButton(window_, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS && have_cursor_) {
    e.fly.mouse_dx_px = x - last_x_;
    e.fly.mouse_dy_px = y - last_y_;
  }
  last_x_ = x;
  last_y_ = y;
  have_cursor_ = true;
  return e;
}

bool AppWindow::should_close() const { return glfwWindowShouldClose(window_) == GLFW_TRUE; }

void AppWindow::set_title(const std::string& title) { glfwSetWindowTitle(window_, title.c_str()); }

void AppWindow::framebuffer_size(uint32_t& width, uint32_t& height) const {
  int w = 0, h = 0;
  glfwGetFramebufferSize(window_, &w, &h);
  width = static_cast<uint32_t>(w > 0 ? w : 0);
  height = static_cast<uint32_t>(h > 0 ? h : 0);
}

}  // namespace texstream::render
