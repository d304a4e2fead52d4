#pragma once
// One run of texstream-render: set-up (scene, device, shaders, cache, server), the lock-step frame loop and
// the summary. Headless: frames go to <output_dir>/frames/frame_NNNNN.png.
//
// Per frame: sample the camera path at virtual time i * frame_time; broad phase over the wide frustum;
// camera-relative offsets and indirect draws; poll the stream client (validated mips land in the staging
// ring); record uploads + main pass + wide metadata pass + compaction (+ the list copy when a streaming cycle
// is due); submit and wait for the fence; publish completed uploads; if a cycle is due, sort the compacted list
// and run the texture state machine (Algorithm 1), which sends requests. Frame latency is the wall time of all
// of that (PNG writing excluded).
#include <filesystem>
#include <string>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"
#include "texstream/render/run_summary.hpp"

namespace texstream::render {

struct RenderRun {
  Config config;
  std::filesystem::path config_file;   // handed to the spawned server (empty: defaults + overrides)
  std::vector<std::string> overrides;  // "part.key=value", handed to the spawned server too
};

Result<RunSummary> run_renderer(const RenderRun& run);

}  // namespace texstream::render
