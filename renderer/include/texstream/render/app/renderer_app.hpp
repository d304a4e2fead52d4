#pragma once
// One run of texstream-render: set-up (scene, device, shaders, cache, server), the lock-step frame loop and
// the summary. Headless: frames go to <output_dir>/frames/frame_NNNNN.png.
//
// Per frame: sample the camera path at virtual time i * frame_time; broad phase over the wide frustum;
// camera-relative offsets and indirect draws; poll the stream client (validated mips land in the staging
// ring); record uploads + main pass + wide metadata pass + compaction (+ the list copy when a streaming cycle
// is due); submit and wait for the fence; publish completed uploads; if a cycle is due, sort the compacted list
// and run the texture state machine (Algorithm 1), which sends requests. Frame latency is the wall time of all
// of that (PNG writing and image-error measurement excluded). Each frame's measurements go to
// <output_dir>/frames.csv (frame_log.hpp).
//
// Modes besides streaming: render.preload_all loads every mip of every texture through the server before
// frame 0 (reference frames, the all-resident baseline); render.blocking_loads loads the whole chain of every
// texture the visibility list names before the next frame draws (the blocking baseline).
#include <filesystem>
#include <string>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"
#include "texstream/render/app/in_process_server.hpp"
#include "texstream/render/measure/run_summary.hpp"

namespace texstream::render {

struct RenderRun {
  Config config;
  std::filesystem::path config_file;   // handed to the spawned server (empty: defaults + overrides)
  std::vector<std::string> overrides;  // "part.key=value", handed to the spawned server too
  // Set: no texstream-server child; this server runs in a thread of this process (in_process_server.hpp).
  InProcessServerFactory in_process_server;
};

// The whole texstream-render command line (main.cpp), shared with texstream-render-inprocess, which passes
// its in-process server factory. `program` names the tool in messages. Returns the process exit code.
int render_main(int argc, char** argv, const char* program, InProcessServerFactory in_process_server = {});

Result<RunSummary> run_renderer(const RenderRun& run);

}  // namespace texstream::render
