#pragma once
// texstream::server::Server on a thread of the renderer's process (render/in_process_server.hpp): the
// in-process loader baseline of texstream-bench path. Same server code as texstream-server: Server::create on
// the segment the renderer created, Server::run until stopped; only the process boundary is gone.
#include <atomic>
#include <memory>
#include <string>
#include <thread>

#include "texstream/common/config.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/render/app/in_process_server.hpp"
#include "texstream/server/dispatch/server.hpp"
#include "texstream/server/storage/posix_storage.hpp"

namespace texstream::bench {

class ThreadServer final : public render::InProcessServer {
 public:
  explicit ThreadServer(const Config& config) : config_(config) {}
  ~ThreadServer() override { stop(); }
  // Local scenes only (storage.origin empty): the remote tiers are not what this baseline prices.
  Status start(const std::string& segment_name) override;
  void stop() override;

 private:
  Config config_;
  std::unique_ptr<Segment> segment_;
  server::PosixStorage storage_;
  std::unique_ptr<server::Server> server_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace texstream::bench
