#pragma once
// Renders single views of a scene offline, with the renderer's own passes (broad phase, pre-pass, main pass,
// wide pass, compaction, prefix read-back) but no streaming: every texture shows its City Colormap colour.
// It is how tests and `texstream-bench visibility` look at what the GPU computed for a view: the compacted
// metadata, the picture (or the id buffer with render.debug_view = mesh_id), the LOD probe, and timings.
// Not used by the frame loop.
#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "texstream/common/camera_path.hpp"
#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"
#include "texstream/render/frame/scene_passes.hpp"
#include "texstream/render/scene/broad_phase.hpp"
#include "texstream/render/scene/gpu_structs.hpp"
#include "texstream/render/scene/scene_data.hpp"

namespace texstream::render {

struct ViewRendererOptions {
  bool lod_probe = false;                // compile the LOD_PROBE variant and return its samples
  std::array<double, 3> scene_offset{};  // added to every mesh origin (and expected in the poses given)
  bool timestamps = false;               // GPU timestamps per pass (ViewResult::pass_times)
  bool stage_geometry = false;           // SceneGpu copies meshes through staging even on unified memory
  bool drop_unsampled = true;            // BroadPhase::drop_unsampled (false: draw every mesh the frusta keep)
};

struct ViewRequest {
  bool feedback = true;   // metadata + wide pass + compaction
  bool read_back = true;  // copy the compacted prefix to the host and return it
  bool capture = true;    // copy the picture to the host and return it
};

struct ViewResult {
  uint32_t width = 0, height = 0;
  std::vector<uint8_t> rgba;               // capture: width * height * 4, rows top to bottom
  uint32_t list_count = 0;                 // the GPU's counter (may exceed the capacity)
  std::vector<gpu::CompactEntry> entries;  // read_back: the used prefix
  std::vector<gpu::LodProbeSample> probe;  // lod_probe: one per pixel
  size_t submitted = 0;                    // meshes the broad phase kept (wide frustum)
  size_t unsampled = 0;                    // of those, dropped: no pixel centre in their passes
  uint32_t main_meshes = 0;                // of those, drawn by the main pass (touch the viewport frustum)
  uint32_t wide_meshes = 0;                // drawn by the wide pass (reach outside the viewport frustum)
  uint32_t main_draws = 0;                 // the indirect draws those took (each covers a run of meshes)
  uint32_t wide_draws = 0;
  PassTimes pass_times;  // ViewRendererOptions::timestamps
  BroadPhaseStats broad_phase;
  double broad_phase_ms = 0;
  double gpu_ms = 0;  // submit to fence (the frame's GPU work, waited for)
};

class ViewRenderer {
 public:
  // `cfg` supplies the device, size, lens, A_m, tau, foreground distance and debug view.
  static Result<std::unique_ptr<ViewRenderer>> create(const Config& cfg, SceneData scene,
                                                      const ViewRendererOptions& options = {});
  ~ViewRenderer();
  ViewRenderer(const ViewRenderer&) = delete;
  ViewRenderer& operator=(const ViewRenderer&) = delete;

  Result<ViewResult> render(const CameraPose& pose, const ViewRequest& request = {});
  const SceneData& scene() const;
  uint32_t validation_errors() const;
  bool probe_is_anisotropic() const;

 private:
  struct Impl;
  explicit ViewRenderer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Decodes one pixel of a render.debug_view = mesh_id picture: the mesh id, or -1 for "no mesh" (the clear
// colour). Inverse of scene.frag's mesh_id_colour.
int64_t decode_mesh_id(uint8_t r, uint8_t g, uint8_t b);

}  // namespace texstream::render
