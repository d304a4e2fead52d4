#include "path_in_process_server.hpp"

#include <spdlog/spdlog.h>

namespace texstream::bench {

Status ThreadServer::start(const std::string& segment_name) {
  if (thread_.joinable()) return make_error(ErrorCode::kInvalidArgument, "in-process server: already started");
  if (!config_.storage.origin.empty()) {
    return make_error(ErrorCode::kUnsupported, "in-process server: storage.origin '" + config_.storage.origin +
                                                   "' is not supported; it serves scene.dir from local files");
  }
  auto segment = Segment::open(segment_name);
  if (!segment) return segment.error();
  segment_ = std::move(*segment);
  auto server = server::Server::create(*segment_, config_.scene.dir, config_.server, storage_);
  if (!server) return server.error();
  server_ = std::move(*server);
  stop_.store(false, std::memory_order_relaxed);
  thread_ = std::thread([this] {
    const server::RunOutcome outcome = server_->run(stop_);
    if (outcome != server::RunOutcome::kStopped) {
      spdlog::error("in-process texture server stopped: {}", server::to_string(outcome));
    }
  });
  return ok_status();
}

void ThreadServer::stop() {
  stop_.store(true, std::memory_order_relaxed);  // run() polls it at least every server.idle_wait_ms
  if (thread_.joinable()) thread_.join();
  server_.reset();  // before the segment it serves
  segment_.reset();
}

}  // namespace texstream::bench
