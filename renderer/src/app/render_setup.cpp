// Set-up of a texstream-render run: the configuration turned into the render stack, the controller and the
// stream client, and render.preload_all (renderer.hpp).
#include <spdlog/spdlog.h>

#include <chrono>
#include <memory>
#include <optional>

#include "renderer.hpp"
#include "texstream/render/window/interactive_session.hpp"

namespace texstream::render {

namespace {

namespace fs = std::filesystem;

// The render stack of a run: the device from render.device and render.validation, the cache from
// cache.*, the passes from render.width_px, height_px and debug_view. `scene_format` is scene.json's
// texture_format (nullopt: mixed).
Result<RenderStackOptions> stack_options(const Config& cfg, const SceneData& scene) {
  const std::optional<TexelFormat> scene_format = scene.manifest.texture_format;
  RenderStackOptions so;
  so.vulkan.device_substring = cfg.render.device;
  so.vulkan.validation = cfg.render.validation;
  // cache.format = auto keeps every texture in its own format; an explicit one must be every texture's.
  so.cache.format = cache_texel_format(cfg.cache.format);
  const std::optional<TexelFormat> all = so.cache.format ? so.cache.format : scene_format;
  so.vulkan.need_bc = !all || is_block_compressed(*all);
  so.cache.eviction = cfg.cache.eviction;
  so.cache.layer_extent = static_cast<uint32_t>(cfg.cache.layer_extent_px);
  so.cache.layers = static_cast<uint32_t>(cfg.cache.layers);
  so.cache.staging_bytes = static_cast<uint64_t>(cfg.render.staging_bytes);
  so.cache.memory_bytes = static_cast<uint64_t>(cfg.cache.memory_bytes);
  // Reference frames show each frame's wanted mips: nothing fades there.
  so.cache.fade_s = cfg.render.load_wanted_before_drawing ? 0.0 : cfg.stream.fade_ms / 1e3;
  auto passes = scene_passes_options(cfg);
  if (!passes) return passes.error();
  so.passes = *passes;
  if (cfg.pages.enabled) {
    GroundPagesOptions ground;
    ground.config = cfg.pages;
    ground.viewport_width = so.passes.width;
    ground.viewport_height = so.passes.height;
    ground.reference = cfg.pages.reference;
    if (scene.manifest.ground) ground.file_path = scene.dir / scene.manifest.ground->pages;
    so.ground = ground;
  }
  return so;
}

}  // namespace

void Renderer::startup_stage(const char* name) {
  const auto t = Clock::now();
  startup_seconds_.emplace_back(name, std::chrono::duration<double>(t - stage_mark_).count());
  stage_mark_ = t;
}

Status Renderer::set_up() {
  output_dir_ = cfg_.render.output_dir;
  std::error_code ec;
  fs::create_directories(output_dir_ / "frames", ec);
  if (ec) return make_error(ErrorCode::kIo, "render.output_dir '" + output_dir_.string() + "': " + ec.message());

  // Start-up stages, timed for the summary (texstream-bench cache compares 1 K with 1 M textures).
  stage_mark_ = Clock::now();
  // Mapped, not read: the start costs the same for any scene size; meshes are checked when first drawn.
  auto scene = SceneData::open(cfg_.scene.dir);
  if (!scene) return scene.error();
  scene_ = std::move(*scene);
  const fs::path path_file =
      cfg_.render.camera_path.empty() ? scene_.dir / scene_.manifest.camera_path : fs::path(cfg_.render.camera_path);
  auto path = CameraPath::load(path_file);
  if (!path) return path.error();
  if (path->keys().empty()) return make_error(ErrorCode::kInvalidArgument, path_file.string() + ": no keyframes");
  path_ = std::make_unique<CameraPath>(std::move(*path));
  lens_ = CameraLens{cfg_.render.fov_y_deg, cfg_.render.offscreen_fov_y_deg,
                     static_cast<double>(cfg_.render.width_px) / static_cast<double>(cfg_.render.height_px),
                     cfg_.render.near_m, cfg_.render.far_m};
  startup_stage("scene_load");

  auto options = stack_options(cfg_, scene_);
  if (!options) return options.error();
  options->stage = [this](const char* name) { startup_stage(name); };
  if (cfg_.render.window) {
    // The window first: the Vulkan instance needs its extensions. R records the flight next to the frames.
    auto session = InteractiveSession::open(static_cast<uint32_t>(cfg_.render.width_px),
                                            static_cast<uint32_t>(cfg_.render.height_px), path_->sample(0.0),
                                            output_dir_ / "recorded_camera_path.txt");
    if (!session) return session.error();
    interactive_ = std::move(*session);
    interactive_->configure(options->vulkan);
  }
  // Load size s and mip bias b: controller.mode adaptive (Eq. 4-7), none (s = s_max, b = 0) or fixed.
  auto controller_params = stream::ControllerParams::from_config(cfg_.controller);
  if (!controller_params) return controller_params.error();
  auto controller = stream::AdaptiveController::create(*controller_params);
  if (!controller) return controller.error();
  controller_ = std::make_unique<stream::AdaptiveController>(std::move(*controller));
  load_bytes_ = controller_->load_bytes();
  // The texture table is the mapped textures.bin, no heap copy, shared by the states, the ledger and the stream
  // client; a copy of the opened scene (a few pointers) keeps the mapping alive for them (host_memory.md).
  auto table_owner = std::make_shared<const SceneData>(scene_);
  table_ = stream::TextureTable(table_owner, table_owner->texture_records());
  states_ = std::make_unique<stream::TextureStates>(table_, static_cast<uint32_t>(cfg_.stream.levels_in_flight));
  mip_use_ = std::make_unique<stream::MipUseLedger>(table_);

  auto stack = RenderStack::create(scene_, *options);
  if (!stack) return stack.error();
  stack_ = std::move(*stack);
  spdlog::info("vulkan device: {}", stack_->context().device_name());
  if (interactive_) TS_TRY(interactive_->attach(stack_->context()));

  if (!cfg_.render.reference_dir.empty()) {
    const ScenePassesOptions& po = stack_->passes().options();
    TS_TRY(record_.compare_with(cfg_.render.reference_dir, output_dir_, po.width, po.height));
  }
  TS_TRY(start_stream_client());
  startup_stage("stream_client");
  if (cfg_.render.preload_all) TS_TRY(preload_all());
  return ok_status();
}

Status Renderer::start_stream_client() {
  stream::StreamClientOptions so;
  so.spawn_server = !run_.in_process_server && cfg_.server.spawn;
  auto client = stream::StreamClient::start(cfg_, table_, scene_.dir, run_.config_file, run_.overrides, so);
  if (!client) return client.error();
  client_ = std::move(*client);
  if (GroundPages* ground = stack_->ground()) client_->set_page_files({scene_.ground_pages}, ground);
  if (run_.in_process_server) {
    in_process_ = run_.in_process_server(cfg_);
    if (!in_process_) return make_error(ErrorCode::kInvalidArgument, "in-process server: the factory made none");
    TS_TRY(in_process_->start(client_->segment().name()));
    spdlog::info("texture server runs in this process (segment '{}')", client_->segment().name());
  }
  return ok_status();
}

Status Renderer::preload_all() {
  // Every texture, its whole chain: the reference frames and the all-resident baseline.
  std::vector<stream::StreamCandidate> all;
  std::vector<uint32_t> ids;
  all.reserve(scene_.texture_records().size());
  ids.reserve(scene_.texture_records().size());
  for (uint32_t t = 0; t < scene_.texture_records().size(); ++t) {
    all.push_back({TextureId(t), 0.0f, 1.0f});
    ids.push_back(t);
  }
  TextureCache& cache = stack_->cache();
  TS_TRY(cache.prepare_textures(ids));  // every entry, and a format check of every texture, up front
  const auto t0 = Clock::now();
  TS_TRY(load_fully(std::move(all), LoadGoal::kWholeScene));
  if (const GroundPages* ground = stack_->ground()) {
    if (ground->file().stored_pages() > ground->frames().frames()) {
      return make_error(ErrorCode::kResourceExhausted,
                        "render.preload_all: the ground's " + std::to_string(ground->file().stored_pages()) +
                            " pages do not fit its " + std::to_string(ground->frames().frames()) +
                            " page frames; raise pages.memory_bytes (now " + std::to_string(cfg_.pages.memory_bytes) +
                            ")");
    }
    TS_TRY(load_ground_wanted(0, true));
  }
  spdlog::info("render.preload_all: {} mips ({:.1f} MB) of {} textures resident in {:.2f} s",
               cache.stats().mips_uploaded, static_cast<double>(cache.stats().bytes_uploaded) / 1e6,
               cache.resident_textures(), std::chrono::duration<double>(Clock::now() - t0).count());
  return ok_status();
}

}  // namespace texstream::render
