#pragma once
// The interactive mode (render.window = true) as one object the frame loop asks three things: the camera pose
// of the next frame (fly camera: mouse + WASD), "show this frame" (swapchain blit + present) and "should we
// stop" (window closed, Esc). It also prints a readout once per second to the console and the window title:
// frame latency, streaming rate, cache use, load size s and mip bias b ("n/a" while the renderer has none),
// and records the flight as a camera path while R is toggled on.
#include <vulkan/vulkan.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "texstream/common/camera_path.hpp"
#include "texstream/common/result.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"
#include "texstream/render/window/app_window.hpp"
#include "texstream/render/window/camera_recorder.hpp"
#include "texstream/render/window/fly_camera.hpp"
#include "texstream/render/window/swapchain_presenter.hpp"

namespace texstream::render {

struct InteractiveReadout {
  double frame_latency_ms = 0;
  uint64_t bytes_uploaded_total = 0;  // the rate is computed from successive totals
  uint64_t textures_resident = 0;
  uint64_t texture_count = 0;
  std::optional<double> load_size_mb;  // s (seed 000 Eq. 4-7)
  std::optional<double> mip_bias;      // b
};

// One readout line (pure, for tests): "latency 12.3 ms | stream 4.50 MB/s | cache 120/4000 textures | s 16.00 MB
// | b n/a".
std::string format_readout(const InteractiveReadout& r, double rate_mb_s);

class InteractiveSession {
 public:
  // Opens the window (before the Vulkan device: the instance needs the window system's extensions).
  static Result<std::unique_ptr<InteractiveSession>> open(uint32_t width, uint32_t height, const CameraPose& start,
                                                          std::filesystem::path recording_file);
  // Fills what VulkanContext needs to present to this window.
  void configure(VulkanContextOptions& options) const;
  // After the device exists: surface and swapchain.
  Status attach(const VulkanContext& ctx);
  // Polls input and moves the fly camera by the wall time since the last call.
  CameraPose next_pose();
  // Shows the frame (`image` in TRANSFER_SRC_OPTIMAL, its frame complete) and updates the readout.
  Status present(VkImage image, uint32_t width, uint32_t height, const InteractiveReadout& readout);
  bool closed() const { return window_->should_close(); }
  // Stops a recording in progress (writes it); called at the end of the run.
  Status finish();
  uint64_t presented() const { return presenter_ ? presenter_->presented() : 0; }

 private:
  using Clock = std::chrono::steady_clock;
  InteractiveSession(std::unique_ptr<AppWindow> window, const CameraPose& start, std::filesystem::path file)
      : window_(std::move(window)), camera_(start), recorder_(std::move(file)) {}

  std::unique_ptr<AppWindow> window_;
  std::unique_ptr<SwapchainPresenter> presenter_;  // after window_: destroyed first
  FlyCamera camera_;
  CameraRecorder recorder_;
  Clock::time_point last_pose_{};
  Clock::time_point recording_start_{};
  Clock::time_point last_readout_{};
  uint64_t last_bytes_ = 0;
  bool first_pose_ = true;
};

}  // namespace texstream::render
