#include "texstream/render/window/interactive_session.hpp"

#include <spdlog/spdlog.h>

#include <cstdio>

namespace texstream::render {

namespace {
// The readout refreshes once per second: often enough to follow a flight, rarely enough to read.
constexpr double kReadoutPeriodS = 1.0;
}  // namespace

std::string format_readout(const InteractiveReadout& r, double rate_mb_s) {
  char s_text[32] = "n/a";
  char b_text[32] = "n/a";
  if (r.load_size_mb) std::snprintf(s_text, sizeof s_text, "%.2f MB", *r.load_size_mb);
  if (r.mip_bias) std::snprintf(b_text, sizeof b_text, "%.2f", *r.mip_bias);
  char line[256];
  std::snprintf(line, sizeof line, "latency %.1f ms | stream %.2f MB/s | cache %llu/%llu textures | s %s | b %s",
                r.frame_latency_ms, rate_mb_s, static_cast<unsigned long long>(r.textures_resident),
                static_cast<unsigned long long>(r.texture_count), s_text, b_text);
  return line;
}

Result<std::unique_ptr<InteractiveSession>> InteractiveSession::open(uint32_t width, uint32_t height,
                                                                     const CameraPose& start,
                                                                     std::filesystem::path recording_file) {
  auto window = AppWindow::open(width, height, "texstream");
  if (!window) return window.error();
  return std::unique_ptr<InteractiveSession>(
      new InteractiveSession(std::move(*window), start, std::move(recording_file)));
}

void InteractiveSession::configure(VulkanContextOptions& options) const {
  options.instance_extensions = AppWindow::required_instance_extensions();
  options.can_present = &AppWindow::can_present;
}

Status InteractiveSession::attach(const VulkanContext& ctx) {
  auto surface = window_->create_surface(ctx.instance());
  if (!surface) return surface.error();
  auto presenter = SwapchainPresenter::create(ctx, *window_, *surface);
  if (!presenter) return presenter.error();
  presenter_ = std::move(*presenter);
  spdlog::info(
      "window: mouse (left button) looks, WASD moves, Q/E down/up, Shift faster, R records the camera "
      "to {}, Esc quits",
      recorder_.file().string());
  return ok_status();
}

CameraPose InteractiveSession::next_pose() {
  const Clock::time_point now = Clock::now();
  const WindowEvents events = window_->poll();
  const double dt = first_pose_ ? 0.0 : std::chrono::duration<double>(now - last_pose_).count();
  first_pose_ = false;
  last_pose_ = now;
  camera_.update(events.fly, dt);
  if (events.toggle_recording) {
    if (recorder_.recording()) {
      if (auto st = recorder_.stop(); !st) {
        spdlog::error("{}", st.error().message);
      } else {
        spdlog::info("camera recording: {} keyframes written to {}", recorder_.keyframes(), recorder_.file().string());
      }
    } else {
      recorder_.start();
      recording_start_ = now;
      spdlog::info("camera recording started (R again stops it)");
    }
  }
  recorder_.add(std::chrono::duration<double>(now - recording_start_).count(), camera_.pose());
  return camera_.pose();
}

Status InteractiveSession::present(VkImage image, uint32_t width, uint32_t height, const InteractiveReadout& readout) {
  TS_TRY(presenter_->present(image, width, height));
  const Clock::time_point now = Clock::now();
  const double since = std::chrono::duration<double>(now - last_readout_).count();
  if (last_readout_ == Clock::time_point{} || since >= kReadoutPeriodS) {
    const double rate = last_readout_ == Clock::time_point{}
                            ? 0.0
                            : static_cast<double>(readout.bytes_uploaded_total - last_bytes_) / 1e6 / since;
    const std::string line = format_readout(readout, rate);
    spdlog::info("{}", line);
    window_->set_title("texstream | " + line + (recorder_.recording() ? " | REC" : ""));
    last_readout_ = now;
    last_bytes_ = readout.bytes_uploaded_total;
  }
  return ok_status();
}

Status InteractiveSession::finish() {
  if (!recorder_.recording()) return ok_status();
  TS_TRY(recorder_.stop());
  spdlog::info("camera recording: {} keyframes written to {}", recorder_.keyframes(), recorder_.file().string());
  return ok_status();
}

}  // namespace texstream::render
