// Cross-key rules of texstream-render's configuration (renderer.hpp): kept apart so that they move into
// Config::validate() in one piece.
#include "renderer.hpp"

namespace texstream::render {

Status check_cross_key_rules(const Config& cfg) {
  if (cfg.render.window && cfg.render.feedback_pairs) {
    return make_error(ErrorCode::kInvalidArgument,
                      "render.feedback_pairs: a measurement of headless runs; it cannot be used with render.window");
  }
  if (cfg.render.preload_all && cfg.render.blocking_loads) {
    return make_error(ErrorCode::kInvalidArgument,
                      "render.preload_all and render.blocking_loads: choose one (both are baselines of their own)");
  }
  return ok_status();
}

}  // namespace texstream::render
