#pragma once
// A texture server that runs inside the renderer's process, on a thread, serving the segment the renderer
// created — the in-process loader baseline of issue 8, which prices the process boundary: same protocol,
// same rings and slots, same server code, but no second process.
//
// The renderer library never links server code (DESIGN "Layout"): it only knows this interface. A tool that
// links both (texstream-render-inprocess, built with texstream-bench) provides the implementation through
// RenderRun::in_process_server. The StreamClient then runs with spawn_server = false: there is no child to
// supervise or restart, so a server that breaks the ring protocol stops streaming for the rest of the run.
#include <functional>
#include <memory>
#include <string>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"

namespace texstream::render {

class InProcessServer {
 public:
  virtual ~InProcessServer() = default;  // implementations stop and join their thread here too
  // Opens the segment `segment_name` (already created by the renderer) and starts serving it.
  virtual Status start(const std::string& segment_name) = 0;
  // Stops serving and joins; the segment must outlive this call. Idempotent.
  virtual void stop() = 0;
};

// Makes the server for one run from the run's configuration (scene.dir, server.*).
using InProcessServerFactory = std::function<std::unique_ptr<InProcessServer>(const Config& config)>;

}  // namespace texstream::render
