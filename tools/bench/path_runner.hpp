#pragma once
// Running texstream-render over a camera path and reading its per-frame log back: the pieces shared by
// texstream-bench path (path_bench.cpp, issue 8) and the Fig. 12 phase of texstream-bench storage
// (storage_fig12.cpp, issue 4). Spawns processes; no analysis (path_analysis.hpp).
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "texstream/common/camera_path.hpp"
#include "texstream/render/measure/frame_log.hpp"
#include "texstream/render/scene/scene_data.hpp"

namespace texstream::bench {

// texstream-bench path --quick: the section of the path around its first cut (1.5 s of the pause before it,
// 2.5 s after), which holds one refinement at rest and one recovery from an instant switch, at 256x144.
inline constexpr double kQuickBeforeCutS = 1.5;
inline constexpr double kQuickAfterCutS = 2.5;
inline constexpr uint32_t kQuickWidth = 256, kQuickHeight = 144;
// The virtual frame time of every path run: 30 Hz.
inline constexpr double kPathFrameTimeS = 0.033333;

// The part of `path` from `before_s` before its first cut to `after_s` after it (the first before_s + after_s
// seconds when it has no cut), re-timed to start at 0.
CameraPath section_around_first_cut(const CameraPath& path, double before_s, double after_s);

// Runs `argv` with stdout and stderr to `log`; returns the exit code (-1: not started, 128 + n: signal n).
int run_process(const std::vector<std::string>& argv, const std::filesystem::path& log);

// Runs a plot script with Debian's python3 (python3-matplotlib) rather than whatever python3 is first on PATH;
// output to `log`. Returns the exit code as run_process.
int run_python(const std::filesystem::path& script, const std::vector<std::string>& args,
               const std::filesystem::path& log);

// cache.* settings under which every texture of the scene is resident at once (render.preload_all): layers
// of one maximum extent (CacheAllocator: square regions, one extent per layer) and memory for every page.
struct ResidentCache {
  uint64_t layer_extent = 4, layers = 0, memory_bytes = 0;
  std::string error;                      // non-empty: the scene cannot be resident at once on lavapipe's sparse limits
  std::vector<std::string> sets() const;  // the --set overrides
};
ResidentCache resident_cache(const render::SceneData& scene);

// How the reference frames are made (docs/design/reference_frames.md): every mip of every texture resident
// before frame 0 (render.preload_all; the scene must fit the cache, ResidentCache), or each frame's sampled
// mips loaded before it is drawn (render.load_wanted_before_drawing; one frame's mips must fit). Both give the
// same frames. The names are texstream-bench path's --reference.
enum class ReferenceMode { kPreload, kLockstepLoad };
inline constexpr const char* kReferencePreload = "preload";
inline constexpr const char* kReferenceLockstepLoad = "lockstep-load";

// The overrides of the reference run: the mode's loads, lock-step, every frame written, no Eq. 8 blending (a
// plain mipmapped texture path): the ground truth (render.reference_dir of the others).
std::vector<std::string> reference_sets(ReferenceMode mode);

// The --set overrides every run over `path_file` shares: scene, path (whole), frame time and size, no PNGs.
std::vector<std::string> path_run_sets(const std::filesystem::path& scene, const std::filesystem::path& path_file,
                                       double frame_time_s, uint32_t width, uint32_t height);

// One texstream-render (or texstream-render-inprocess) run into `dir`: command.txt (to rerun it by hand),
// log.txt, and the renderer's frames.csv, read back.
struct RenderRun {
  std::filesystem::path bin;     // folder of the renderer binaries
  std::filesystem::path config;  // --config (empty: built-in defaults)
  std::filesystem::path dir;     // render.output_dir (emptied first)
  std::vector<std::string> sets;
  bool in_process = false;
};
struct RenderOutcome {
  int exit_code = -1;
  double wall_s = 0;    // the whole process, start-up and preload included
  std::string failure;  // empty: it ran and its frames.csv was read
  std::vector<render::FrameRecord> frames;
};
RenderOutcome run_renderer(const RenderRun& run);

}  // namespace texstream::bench
