#pragma once
// Private to app/: the frame loop of texstream-render (renderer_app.hpp has the public entry, run_renderer).
// One class in four files, one idea each:
//   renderer_app.cpp       the loop and one frame, top-down (seed 000 Algorithm 1 around the rooms below);
//   render_setup.cpp       the configuration turned into the render stack, the controller and the stream
//                          client;
//   completion_intake.cpp  the three ways completions come in (real time, lock-step, whole chains) and a
//                          streaming cycle;
//   server_checks.cpp      when a server that cannot start or refuses the scene ends the run;
// The objects it draws with are the RenderStack's (frame/render_stack.hpp), the per-frame record and the
// summary's per-frame part are RunRecord's (measure/run_record.hpp).
#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "texstream/common/camera_path.hpp"
#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"
#include "texstream/render/app/renderer_app.hpp"
#include "texstream/render/frame/render_stack.hpp"
#include "texstream/render/measure/run_record.hpp"
#include "texstream/render/scene/camera.hpp"
#include "texstream/render/scene/scene_data.hpp"
#include "texstream/stream/adaptive_controller.hpp"
#include "texstream/stream/mip_use_ledger.hpp"
#include "texstream/stream/stream_client.hpp"
#include "texstream/stream/texture_states.hpp"

namespace texstream::render {

class InteractiveSession;

class Renderer {
 public:
  using Clock = std::chrono::steady_clock;
  // render.preload_all ends with an error once this many spawned servers in a row died before attaching to
  // the segment: a server that cannot start (a bad option, a missing library, a wrong binary) does not start
  // on the next try either, and the restart back-off would otherwise stretch each round to the colormap-only
  // retry period (30 s). A streaming run goes on drawing the colormap and keeps retrying, as after any crash;
  // a lock-step run ends at the first death (take_completions).
  static constexpr uint64_t kMaxDeathsBeforeAttach = 3;

  explicit Renderer(const RenderRun& run);
  ~Renderer();
  Result<RunSummary> run();

 private:
  // ---- render_setup.cpp ----
  Status set_up();
  // The stream client (and an in-process server, if the run has one).
  Status start_stream_client();
  // render.preload_all: every mip of every texture, before frame 0.
  Status preload_all();
  // The time since the previous start-up part, under `name` (RunSummary::startup_seconds).
  void startup_stage(const char* name);

  // ---- renderer_app.cpp ----
  Status render_frame(uint64_t index, bool last);
  // Frame 0's parts go into the summary after set_up()'s stages: the time since the previous part.
  void first_frame_stage(const char* name);
  Result<RunSummary> finish();
  FrameCounters counters() const;
  ControllerReadout controller_readout() const;

  // ---- completion_intake.cpp ----
  // Completions that arrived since the last frame, validated by the client, into the staging ring: real
  // time (at most controller.load_time_ms of the frame) or lock-step (every answer to the previous cycle).
  // Returns the time waited for the server (lock-step), which is not frame latency.
  Result<Clock::duration> take_completions();
  // The ground's pages (RenderStack::ground): requests for what the frame's needbuffer wants (pages.*).
  void request_ground_pages(uint64_t frame, const CameraPose& pose);
  // render.load_wanted_before_drawing: every ground page the probe frame wants, loaded before it is drawn;
  // `whole` (render.preload_all): every stored page.
  Status load_ground_wanted(uint64_t index, bool whole);
  // A streaming cycle (Algorithm 1, LoadTextures) over the compacted list the frame read back.
  // `first` runs right after the new generation starts, before the cycle's mips are requested.
  void start_cycle(const std::vector<stream::StreamCandidate>& candidates, const std::function<void()>& first = {});
  std::vector<stream::StreamCandidate> read_candidates();
  // How far load_fully() loads each texture and what an eviction on the way means.
  enum class LoadGoal : uint8_t {
    kWholeScene,    // the whole chain (level 0); an eviction is an error: the preload must fit the cache
    kWholeChains,   // the whole chain; stop at the first eviction (a visible set larger than the cache cannot
                    // be made fully resident)
    kWantedLevels,  // down to floor(desired_mip); evicting layers filled before the load is fine (their
                    // textures are loaded again if wanted), evicting one filled by this load is an error: the
                    // textures of `wanted` do not fit the cache together
  };
  // Loads every texture in `wanted` as far as `goal` says, waiting for the server and uploading as it goes:
  // render.preload_all before frame 0 (kWholeScene), render.blocking_loads (kWholeChains) and
  // render.load_wanted_before_drawing (kWantedLevels) each frame.
  Status load_fully(std::vector<stream::StreamCandidate> wanted, LoadGoal goal);
  // render.load_wanted_before_drawing: draws frame `index` (`rec`) with feedback only, reads its list back and
  // loads every texture on it to its wanted level, so the frame drawn next samples resident mips only.
  Status load_wanted(const FrameRecording& rec, uint64_t index);
  // A submission that only carries the mips committed so far (no drawing, no geometry).
  Status upload_now();
  // Hands what the cache learnt (published, rejected, failed mips; evictions) to the texture states and the
  // mip-use ledger, which the frame loop alone feeds: before they are read, and once a frame.
  void tell_states();

  // ---- server_checks.cpp ----
  // An error once kMaxDeathsBeforeAttach servers in a row died before attaching (render.preload_all).
  Status server_can_start() const;
  // An error once `limit` servers in a row refused their configuration (exit status 2) before attaching: a
  // streaming run would otherwise draw the colormap for ever, restarting a server that can never start, and
  // report success. kMaxDeathsBeforeAttach during the run; 1 at its end (a short run ends before a third
  // spawn). Crashes keep the colormap-and-retry rule (docs/faults.md).
  Status server_not_refusing(uint64_t limit) const;
  // server.spawn = false: a standalone server refused the segment (another scene): the run ends, naming it.
  Status standalone_server_not_refusing() const;

  const RenderRun& run_;
  const Config& cfg_;
  std::filesystem::path output_dir_;
  SceneData scene_;  // before the stack, which reads it until it is gone
  std::unique_ptr<CameraPath> path_;
  CameraLens lens_{};
  std::unique_ptr<RenderStack> stack_;
  std::unique_ptr<stream::TextureStates> states_;
  // The cache's residency and which mips the view displayed: the mip deficit and the wasted bytes
  // (docs/design/stream_metrics.md).
  std::unique_ptr<stream::MipUseLedger> mip_use_;
  // The latest visibility list read back (the deficit's list on the frames in between); empty before the first.
  std::vector<stream::StreamCandidate> last_list_;
  bool have_list_ = false;
  // Seed 000 §3.4: s and b for each cycle from the measured frame latencies (docs/controller.md).
  std::unique_ptr<stream::AdaptiveController> controller_;
  std::unique_ptr<stream::StreamClient> client_;
  // After client_: destroyed first, so the in-process server's thread is gone before the segment.
  std::unique_ptr<InProcessServer> in_process_;
  std::unique_ptr<InteractiveSession> interactive_;  // render.window = true only
  RunRecord record_;

  Clock::time_point run_start_{};
  Clock::time_point stage_mark_{};  // startup_stage() and first_frame_stage(): end of the previous part
  std::vector<std::pair<std::string, double>> startup_seconds_;  // RunSummary::startup_seconds
  uint64_t cycles_ = 0;
  uint64_t last_cycle_sent_ = 0;
  uint64_t load_bytes_ = 0;
  uint64_t deaths_before_frames_ = 0;  // server deaths before frame 0 (render.lockstep allows none after it)
  // The previous frame's pose: the ground's HotSpot (the turn per frame) and stream.fade_when = still.
  std::optional<CameraPose> last_pose_;
  stream::TextureTable table_;  // the scene's texture table (a view of textures.bin) for every streaming part
};

}  // namespace texstream::render
