#pragma once
// One frame's plan, the same for every renderer variant (the frame loop and ViewRenderer): the broad phase
// over the wide frustum (the wide pass needs those meshes too), split by the viewport's frustum (main pass /
// wide pass, seed 000 §3.2), meshes that cover no pixel centre of their pass dropped, the rest made resident
// (geometry queued for the frame's command buffer, their textures' table entries written), the draw lists
// and the frame constants written. What is left to do is RenderStack::submit.
#include <cstddef>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"
#include "texstream/render/frame/render_stack.hpp"
#include "texstream/render/scene/broad_phase.hpp"
#include "texstream/render/scene/camera.hpp"
#include "texstream/render/scene/frame_recording.hpp"

namespace texstream::render {

struct FramePlanOptions {
  bool drop_unsampled = true;        // BroadPhase::drop_unsampled (false: draw every mesh the frusta keep)
  BroadPhaseStats* stats = nullptr;  // the broad phase's counters, if wanted
  // The compaction keeps every mesh with a fragment (τ = 0 instead of stream.tau): a list that names every
  // texture the frame samples (render.load_wanted_before_drawing).
  bool keep_every_mesh = false;
  // The ground (RenderStack::ground) writes its needbuffer in this frame (read back after it, GroundPages::plan).
  bool ground_needs = true;
  // "broad_phase", "make_resident", "texture_entries", "draw_list", each as it ends.
  StepHook step;
};

struct FramePlan {
  FrameRecording rec;    // the draw lists and pass constants; feedback and read_back_list are the caller's
  ViewportSplit split;   // the runs of RenderStack::visible(): [0, main_end) main pass, the rest wide pass
  size_t submitted = 0;  // meshes the broad phase kept (wide frustum)
  size_t unsampled = 0;  // of those, dropped: no pixel centre in their passes
};

// Plans the frame seen by `cam` on `stack`; the meshes it draws are left in stack.visible(). `cfg` supplies
// the lens and the frame constants' parameters (frame_constants.hpp).
Result<FramePlan> plan_frame(RenderStack& stack, const Camera& cam, const Config& cfg,
                             const FramePlanOptions& options = {});

}  // namespace texstream::render
