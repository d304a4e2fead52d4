#pragma once
// What stream_client.cpp and stream_client_pages.cpp (StreamClient's page requests) share: the helpers of
// the client's IPC timing. Private to the stream library.
#include <chrono>
#include <cstdint>

#include "texstream/stream/stream_client.hpp"

namespace texstream::stream {

namespace detail {
inline uint64_t elapsed_ns(std::chrono::steady_clock::time_point since) {
  return static_cast<uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - since).count());
}
}  // namespace detail

// One client call's time, less the sink's, added to the open frame's IPC time. Nested calls count once.
class StreamClient::IpcScope {
 public:
  explicit IpcScope(StreamClient& c) : c_(c) {
    if (c_.ipc_depth_++ == 0) {
      c_.sink_ns_ = 0;
      start_ = std::chrono::steady_clock::now();
    }
  }
  ~IpcScope() {
    if (--c_.ipc_depth_ == 0) {
      const uint64_t total = detail::elapsed_ns(start_);
      c_.frame_ipc_ns_ += total > c_.sink_ns_ ? total - c_.sink_ns_ : 0;
    }
  }
  IpcScope(const IpcScope&) = delete;
  IpcScope& operator=(const IpcScope&) = delete;

 private:
  StreamClient& c_;
  std::chrono::steady_clock::time_point start_{};
};

}  // namespace texstream::stream
