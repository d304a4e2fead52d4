// texstream-render-inprocess: texstream-render with its texture server on a thread of the same process
// (texstream-bench path's in-process loader baseline: what the process boundary costs). Same command line,
// same configuration keys, same outputs (summary.json, frames.csv) as texstream-render.
#include "path_in_process_server.hpp"
#include "texstream/render/app/renderer_app.hpp"

int main(int argc, char** argv) {
  return texstream::render::render_main(argc, argv, "texstream-render-inprocess", [](const texstream::Config& c) {
    return std::unique_ptr<texstream::render::InProcessServer>(std::make_unique<texstream::bench::ThreadServer>(c));
  });
}
