#include "texstream/render/frame/frame_plan.hpp"

#include "texstream/render/frame/frame_constants.hpp"

namespace texstream::render {

Result<FramePlan> plan_frame(RenderStack& stack, const Camera& cam, const Config& cfg,
                             const FramePlanOptions& options) {
  auto step = [&](const char* name) {
    if (options.step) options.step(name);
  };
  const SceneData& scene = stack.scene();
  BroadPhase& broad_phase = stack.broad_phase();
  std::vector<uint32_t>& visible = stack.visible();
  FramePlan plan;
  FrameRecording& rec = plan.rec;

  // Broad phase over the wide frustum: the wide pass needs those meshes too.
  broad_phase.query(Frustum::from_matrix(cam.wide_proj * cam.view), cam.position, visible, options.stats);
  plan.submitted = visible.size();
  const ScenePassesOptions& po = stack.passes().options();
  rec.main = main_pass_constants(cam);
  rec.wide = wide_pass_constants(cam, cfg.render.fov_y_deg, cfg.render.offscreen_fov_y_deg, po.height, po.wide_height);
  // Touching / outside the viewport's frustum: the main pass draws the first run, the wide pass the second
  // (W = 1 for meshes outside the viewport, seed 000 §3.2). Meshes that cover no pixel centre of the pass
  // drawing them have no fragment: neither uploaded nor drawn (both tests in one pass over the records).
  const Frustum viewport = Frustum::from_matrix(cam.proj * cam.view);
  if (options.drop_unsampled) {
    const uint32_t bits = stack.context().properties().limits.subPixelPrecisionBits;
    plan.split = broad_phase.split_and_drop_unsampled(
        viewport, SampleGrid::from_columns(rec.main.view_proj.m, po.width, po.height, bits),
        SampleGrid::from_columns(rec.wide.view_proj.m, po.wide_width, po.wide_height, bits), cam.position, visible);
  } else {
    plan.split = broad_phase.split_by_viewport(viewport, cam.position, visible);
  }
  plan.unsampled = plan.submitted - visible.size();
  step("broad_phase");

  // Meshes drawn for the first time: checked, their geometry queued for this frame's command buffer and their
  // textures checked, so the frame draws every one of them.
  std::vector<uint32_t>& new_textures = stack.new_textures();
  new_textures.clear();
  TS_TRY(stack.scene_gpu().make_resident(scene, visible, &new_textures));
  step("make_resident");
  TS_TRY(stack.cache().prepare_textures(new_textures));
  step("texture_entries");
  // Each drawn mesh names its texture's table slot: the textures drawn now keep theirs, those new to the table
  // get one and an entry, and the slots of textures neither drawn nor cached are freed for reuse. Safe on every
  // path (lock-step, reference frames, preload_all, the window): each submission is waited for before the next
  // frame is planned (RenderStack::submit), and the submissions of this frame (its twin, its reference probe,
  // load rounds) draw these meshes, whose slots this frame holds until the next plan.
  TextureCache& cache = stack.cache();
  cache.begin_frame();
  stack.scene_gpu().write_draws(scene, visible, cam.position, plan.split, cache.texture_slots(), rec);
  TS_TRY(cache.write_slots());
  step("draw_list");
  // ScenePasses::record adds the view mode and the feedback bit.
  const SceneGpu& gpu = stack.scene_gpu();
  std::array<uint32_t, 4> extents{};
  for (uint32_t i = 0; i < stack.cache().plane_count(); ++i) extents[i] = stack.cache().layer_extent(i);
  gpu::FrameUniforms fu = frame_uniforms(cam, cfg, gpu.mesh_count(), gpu.compact_capacity(), extents);
  if (options.keep_every_mesh) fu.flags.z = 0;  // the weight cutoff τ in kWeightFixedScale units
  stack.scene_gpu().set_frame_uniforms(fu);
  if (GroundPages* ground = stack.ground()) ground->write_uniforms(cam.position, options.ground_needs);
  return plan;
}

}  // namespace texstream::render
