// When a texture server that cannot start, or refuses the scene, ends the run (renderer.hpp).
#include "renderer.hpp"

namespace texstream::render {

Status Renderer::server_can_start() const {
  TS_TRY(standalone_server_not_refusing());
  const uint64_t deaths = client_->stats().server_deaths_before_attach;
  if (deaths < kMaxDeathsBeforeAttach) return ok_status();
  return make_error(ErrorCode::kPeerDead,
                    "texstream-server died before attaching to the segment " + std::to_string(deaths) +
                        " times in a row (last: " + client_->last_server_exit() +
                        "); its own messages are above. Check server.executable and the [server] keys");
}

Status Renderer::standalone_server_not_refusing() const {
  if (client_->standalone_refused_by() == 0) return ok_status();
  return make_error(ErrorCode::kPeerDead, client_->last_server_exit() +
                                              ". Start texstream-server with this renderer's scene (--scene, "
                                              "scene.dir), or run this renderer on the server's scene");
}

Status Renderer::server_not_refusing(uint64_t limit) const {
  TS_TRY(standalone_server_not_refusing());
  const uint64_t refusals = client_->server_refusals_before_attach();
  if (refusals < limit) return ok_status();
  return make_error(ErrorCode::kPeerDead,
                    "texstream-server refused to start, " + std::to_string(refusals) +
                        (refusals == 1 ? " time" : " times") + " in a row (last: " + client_->last_server_exit() +
                        ": bad arguments, configuration or scene); its own messages are above. Check the "
                        "[server] and [storage] keys and scene.dir");
}

}  // namespace texstream::render
