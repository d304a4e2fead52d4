#pragma once
// Every parameter of texstream, one struct per part, read from one TOML file (config/default.toml) and
// overridden by `--set part.key=value`. Units are in the key names. Each key is declared once, in
// config.cpp's `visit_keys`, with its type, default, range and documentation; the parser, the `--set`
// override, the documentation generator (docs/config.md) and the validation all come from that one list.
// Unknown keys and out-of-range values are start-up errors that name the key — never silently clamped.
// A key with a fixed set of values is an enum with one name table (config_choice.hpp), declared below.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "texstream/common/config_choice.hpp"
#include "texstream/common/page_modes.hpp"
#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream {

// ---- keys with a fixed set of values: each enum's one table of names and docs ----

enum class LogLevel : uint8_t { kTrace, kDebug, kInfo, kWarn, kError };  // server.log_level
template <>
struct ChoiceTable<LogLevel> {
  // spdlog's level names: texstream-server hands the name to spdlog::level::from_str.
  static constexpr std::array<ChoiceEntry<LogLevel>, 5> kEntries{{{LogLevel::kTrace, "trace", ""},
                                                                  {LogLevel::kDebug, "debug", ""},
                                                                  {LogLevel::kInfo, "info", ""},
                                                                  {LogLevel::kWarn, "warn", ""},
                                                                  {LogLevel::kError, "error", ""}}};
};

enum class RamCachePolicy : uint8_t { kLevel, kLru };  // server.cache_policy
template <>
struct ChoiceTable<RamCachePolicy> {
  static constexpr std::array<ChoiceEntry<RamCachePolicy>, 2> kEntries{
      {{RamCachePolicy::kLevel, "level",
        "seed 002 Eq. 4 discard priority; measured higher hit rates than lru at every budget"},
       {RamCachePolicy::kLru, "lru", ""}}};
};

enum class DebugView : uint8_t { kNone, kMip, kWeight, kMeshId, kPageLevel, kPageResidency };  // render.debug_view
template <>
struct ChoiceTable<DebugView> {
  static constexpr std::array<ChoiceEntry<DebugView>, 6> kEntries{
      {{DebugView::kNone, "none", ""},
       {DebugView::kMip, "mip", "displayed mip as grey"},
       {DebugView::kWeight, "weight", "heat map"},
       {DebugView::kMeshId, "mesh_id", ""},
       {DebugView::kPageLevel, "page_level",
        "the ground's pages: red = (level shown + 1) x 16, green = (level wanted + 1) x 16; meshes blue"},
       {DebugView::kPageResidency, "page_residency",
        "the ground's pages: green = the wanted page, yellow = an ancestor, red = nothing resident; meshes blue"}}};
};

// How the City Colormap colour is blended with the sampled colour (stream.blend; docs/design/blend.md).
enum class BlendMode : uint8_t {
  kConverge,        // by a power of the missing fraction ((displayed - wanted) / M_max)^n (stream.blend_exponent)
  kConvergeLinear,  // by the missing fraction itself: smoother, but costs more error while levels arrive
  kSeed,            // seed 000 Eq. 8: by the displayed level, M / M_max (never 0 for a texture seen from afar)
};
template <>
struct ChoiceTable<BlendMode> {
  static constexpr std::array<ChoiceEntry<BlendMode>, 3> kEntries{
      {{BlendMode::kConverge, "converge",
        "by the fraction of levels still missing to the power stream.blend_exponent; exact once the wanted level is "
        "resident"},
       {BlendMode::kConvergeLinear, "converge_linear", "by the fraction of levels still missing"},
       {BlendMode::kSeed, "seed", "seed 000 Eq. 8, by the displayed level"}}};
};

// When a newly resident level fades in (stream.fade_when; docs/design/blend.md, "Fading while still").
enum class FadeWhen : uint8_t {
  kStill,   // only while the camera is still: a pop shows there; in motion levels show at once
  kAlways,  // every arrival, moving or not
};
template <>
struct ChoiceTable<FadeWhen> {
  static constexpr std::array<ChoiceEntry<FadeWhen>, 2> kEntries{
      {{FadeWhen::kStill, "still", "only while the camera is still; a frame whose camera moved ends every fade"},
       {FadeWhen::kAlways, "always", "every arrival, moving or not"}}};
};

// Streaming controller mode (controller.mode): docs/controller.md.
enum class ControllerMode : uint8_t {
  kAuto,   // target 2x the latency without streaming, measured; s and b from it (headroom_controller.hpp)
  kSeed,   // seed 000 §3.4 Eq. 4-7 with α
  kNone,   // s = s_max, b = 0: the seed's "no adaptive algorithms" baseline (Tables 3-5)
  kFixed,  // s and b fixed by configuration (benchmarks)
};
template <>
struct ChoiceTable<ControllerMode> {
  static constexpr std::array<ChoiceEntry<ControllerMode>, 5> kEntries{
      {{ControllerMode::kAuto, "auto", "target set from the measured latency without streaming"},
       {ControllerMode::kSeed, "seed", "seed 000 Eq. 4-7 with alpha_ms"},
       {ControllerMode::kSeed, "adaptive", "the old name of seed"},
       {ControllerMode::kNone, "none", "s = s_max, b = 0: the seed's baseline"},
       {ControllerMode::kFixed, "fixed", "s and b from fixed_load_mb and fixed_bias"}}};
};

enum class CacheFormat : uint8_t { kAuto, kRgba8, kBc1, kBc3, kBc7 };  // cache.format
template <>
struct ChoiceTable<CacheFormat> {
  static constexpr std::array<ChoiceEntry<CacheFormat>, 5> kEntries{{{CacheFormat::kAuto, "auto", "each texture's own"},
                                                                     {CacheFormat::kRgba8, "rgba8", ""},
                                                                     {CacheFormat::kBc1, "bc1", ""},
                                                                     {CacheFormat::kBc3, "bc3", ""},
                                                                     {CacheFormat::kBc7, "bc7", ""}}};
};
// The GPU cache's texel format: auto (nullopt) keeps every texture in its own; an explicit one must be every
// texture's.
constexpr std::optional<TexelFormat> cache_texel_format(CacheFormat format) {
  switch (format) {
    case CacheFormat::kRgba8:
      return TexelFormat::kRgba8;
    case CacheFormat::kBc1:
      return TexelFormat::kBc1;
    case CacheFormat::kBc3:
      return TexelFormat::kBc3;
    case CacheFormat::kBc7:
      return TexelFormat::kBc7;
    case CacheFormat::kAuto:
      break;
  }
  return std::nullopt;
}

enum class DiskCachePolicy : uint8_t { kLru, kFifo };  // storage.disk_cache_policy
template <>
struct ChoiceTable<DiskCachePolicy> {
  static constexpr std::array<ChoiceEntry<DiskCachePolicy>, 2> kEntries{
      {{DiskCachePolicy::kLru, "lru", ""}, {DiskCachePolicy::kFifo, "fifo", "seed 002's"}}};
};

// ---- one struct per part ----

struct SceneConfig {
  std::string dir = "scenes/default";  // scene folder written by texstream-gen
};

struct ProtocolConfig {
  std::string segment_name;              // empty: "texstream-<renderer pid>"
  int64_t request_ring_capacity = 4096;  // records, power of two
  int64_t completion_ring_capacity = 4096;
  int64_t staging_slot_count = 1024;
  int64_t staging_slot_bytes = 0;  // 0: the scene's largest mip (effective_staging)
  double heartbeat_timeout_ms =
      1400;  // hung after this long without progress; + one watchdog poll stays < 1.5 s (issue 9)
};

// The staging slots a renderer creates: protocol.staging_slot_bytes, or when it is 0 (auto) the scene's
// largest mip (`largest_mip_bytes`), 4 KiB aligned, at least kMinAutoSlotBytes, at most the protocol's 64 MiB;
// with auto slots the count is lowered so that the pool stays within kMaxAutoStagingBytes and within half of
// `shm_free_bytes` (the free space of /dev/shm: the segment is backed at creation, and containers often mount
// only 64 MiB there), at least 4 slots.
struct StagingShape {
  uint64_t slot_count = 0;
  uint64_t slot_bytes = 0;
};
inline constexpr uint64_t kMinAutoSlotBytes = 64u << 10;
inline constexpr uint64_t kMaxAutoStagingBytes = 512ull << 20;
StagingShape effective_staging(const ProtocolConfig& protocol, uint64_t largest_mip_bytes,
                               uint64_t shm_free_bytes = UINT64_MAX);

struct ServerConfig {
  bool spawn = true;           // false: no child; a standalone texstream-server serves segment_name
  std::string executable;      // empty: texstream-server next to texstream-render
  int64_t worker_threads = 2;  // read + decode workers (2-core default)
  int64_t ram_cache_bytes = 256ll << 20;
  double idle_wait_ms = 20;  // futex wait between doorbells (also paces the heartbeat)
  LogLevel log_level = LogLevel::kInfo;
  RamCachePolicy cache_policy = RamCachePolicy::kLevel;  // RAM cache eviction
  double rate_limit_mb_s = 0;                            // storage read rate cap in MB/s (0: unlimited), seed 002 §3.3
  int64_t remote_fetches_in_flight = 4;  // bound on concurrent fetches from a remote/slow origin (seed 002: 1)
  bool batch_scheduling = true;          // texstream-server runs SCHED_BATCH: never preempts the frame on wake-up
};

struct RenderConfig {
  std::string device = "llvmpipe";  // substring of the Vulkan device name; empty: the first device
  bool validation = false;          // Khronos validation layer (tests turn it on)
  bool window = false;              // GLFW window instead of headless
  int64_t width_px = 960;
  int64_t height_px = 540;
  int64_t frames = 90;            // headless: frames to render (0: the whole camera path)
  double frame_time_ms = 33.333;  // virtual time per frame along the camera path
  bool lockstep = false;          // each frame first takes every answer to the previous cycle (reproducible)
  bool pace_frames = false;       // real time: frame N starts no earlier than N × frame_time_ms (a fixed-rate display)
  std::string camera_path;        // empty: <scene>/camera_path.txt
  std::string output_dir = "out";
  int64_t write_every_frames = 10;  // write every Nth frame as PNG (0: none; the last frame always)
  double fov_y_deg = 60;
  double offscreen_fov_y_deg = 75;  // wider off-screen FOV whose meshes are requested at W = 1 (seed 000 §3.2)
  double near_m = 1;
  double far_m = 20000;
  double headlight_ambient = 0.6;      // headlight: camera-facing surfaces 1, edge-on ones this fraction (1 = unlit)
  int64_t staging_bytes = 32ll << 20;  // host-visible staging ring for uploads into the cache
  DebugView debug_view = DebugView::kNone;
  bool feedback = true;         // visibility metadata pass + compaction (off: for cost measurements)
  bool feedback_pairs = false;  // measurement: each frame also drawn without feedback (latency_off_ms)
  bool preload_all = false;     // load every mip of every texture before frame 0: no streaming (reference frames)
  bool blocking_loads = false;  // each frame loads the full chain of every visible texture before drawing
  // Reference frames without the scene resident: each frame is first drawn with feedback only, then every mip it
  // samples is loaded (down to floor of its wanted level, no budget, no bias), then it is drawn for real.
  bool load_wanted_before_drawing = false;
  std::string reference_dir;  // a reference run's output folder: per-frame MSE/PSNR/SSIM against its frames
};

struct StreamConfig {
  double tau = 150;                        // mesh weight cutoff (seed 000 §3.3, Table 2)
  double max_anisotropy = 16;              // A_m for the mip-level metadata; sampling uses A_m / 2 (seed 000 §3.2)
  int64_t max_requests_in_flight = 2048;   // pre-queue depth sent to the server per cycle
  int64_t max_mips_per_cycle = 512;        // upload budget per streaming cycle
  int64_t levels_in_flight = 8;            // most levels of one texture requested at once (1: seed Algorithm 1)
  bool colormap_blend = true;              // colormap blended in while mips arrive; false samples directly
  BlendMode blend = BlendMode::kConverge;  // how (colormap_blend = true)
  int64_t blend_exponent = 3;              // converge: the power of the missing fraction (docs/design/blend.md)
  double fade_ms = 200;                    // a newly resident level fades in over this much path time; 0: at once
  FadeWhen fade_when = FadeWhen::kStill;   // fade only while the camera is still, or always
  double foreground_distance_m = 500;      // Eq. 2: w_d falls from 1 at the camera to 0 at this view depth
};

// Adaptive streaming controller, seed 000 §3.4 Eq. 4-7 and Table 2.
struct ControllerConfig {
  ControllerMode mode = ControllerMode::kAuto;
  double target_ms = 0;           // auto: cap on the target (0: 2x the measured latency without streaming)
  double target_min_ms = 16.667;  // auto: the target is never below one 60 Hz refresh
  double pace_share = 1.0;        // auto: a frame's streaming work stays within this share of f (0: no pacing)
  double alpha_ms = 16;           // seed: α, target maximum frame latency
  double beta = 8;                // β: maximum mip bias
  double s_min_mb = 0.065;        // minimum load size (one 64 KiB sparse block)
  double s_max_mb = 64;           // maximum load size
  double load_time_ms = 16;       // maximum time one streaming cycle may spend loading
  double fixed_load_mb = 16;      // mode = fixed: load size s
  double fixed_bias = 0;          // mode = fixed: mip bias b
};

enum class CacheEviction : uint8_t { kLru, kRing };  // cache.eviction
template <>
struct ChoiceTable<CacheEviction> {
  static constexpr std::array<ChoiceEntry<CacheEviction>, 2> kEntries{
      {{CacheEviction::kLru, "lru",
        "textures of any size share layers (2D buddy allocator); when memory or address space is short, the "
        "texture seen longest ago goes, never one the current cycle uses"},
       {CacheEviction::kRing, "ring", "seed 000 §3.6: one texture size per layer, the oldest layer goes"}}};
};

struct CacheConfig {
  CacheFormat format = CacheFormat::kAuto;  // the texel format of the GPU cache
  CacheEviction eviction = CacheEviction::kLru;
  int64_t layer_extent_px = 0;         // side of one cache layer (0: from the device, the budget and the scene)
  int64_t layers = 0;                  // array layers of the sparse cache image (0: from the device and the budget)
  int64_t memory_bytes = 128ll << 20;  // GPU memory the cache's bound sparse pages may use (never exceeded)
};

// The scene's ground as one huge texture in pages (scene.json "ground", issue 28; docs/design/pages.md).
struct PagesConfig {
  bool enabled = true;                // draw and stream the ground when the scene has one
  int64_t memory_bytes = 64ll << 20;  // GPU memory of the page frames (bordered pages, one per array layer)
  int64_t per_frame = 16;             // pages requested per frame at most (seed 004's fixed page budget)
  pages::PageHeuristic heuristic = pages::PageHeuristic::kPixelSum;
  pages::AncestorOrder order = pages::AncestorOrder::kIntern;
  bool noise_scaling = false;
  bool noise_skipping = false;  // order = extern only
  int64_t locked_levels = 4;    // the coarsest levels are never evicted (seed 004 §4.3.1)
  pages::DiscardRule discard = pages::DiscardRule::kLru;
  int64_t needbuffer_step = 4;  // every Nth pixel per axis writes the needbuffer
  bool reference = false;       // the ground as one ordinary mipmapped texture, nothing streamed (seams check)
};

// Where texture bytes come from and the tiers in front of it (issue 4, seed 002 §3.2 Meta-texture Server).
struct StorageConfig {
  std::string origin;                    // empty: scene.dir on the local file system; else a path or http(s):// URL
  std::string disk_cache_dir;            // empty: no disk cache
  int64_t disk_cache_bytes = 1ll << 30;  // byte budget of the disk cache
  DiskCachePolicy disk_cache_policy = DiskCachePolicy::kLru;
  int64_t connect_timeout_ms = 2000;   // http: TCP/TLS connect
  int64_t request_timeout_ms = 10000;  // http: one whole range request
  int64_t low_speed_bytes_s = 1024;    // http: slower than this for low_speed_time_s aborts (slowloris)
  int64_t low_speed_time_s = 3;
  int64_t retries = 2;            // http: extra attempts after a transient failure
  int64_t retry_backoff_ms = 50;  // http: first back-off, doubled per retry
  bool slow_enabled = false;      // wrap the origin in the slow-storage emulation below
  double slow_latency_ms = 0;
  double slow_jitter_ms = 0;
  double slow_bandwidth_mb_s = 0;  // 0: unlimited
  double slow_stall_probability = 0;
  double slow_stall_ms = 0;
  double slow_failure_rate = 0;
  int64_t slow_seed = 1;
};

struct Config {
  SceneConfig scene;
  ProtocolConfig protocol;
  ServerConfig server;
  RenderConfig render;
  StreamConfig stream;
  ControllerConfig controller;
  CacheConfig cache;
  StorageConfig storage;
  PagesConfig pages;

  // Relations between fields (filament validateConfig style); messages name the keys.
  Status validate() const;
};

// Reads `file` (empty: defaults only), then applies each "part.key=value" override in order.
Result<Config> load_config(const std::filesystem::path& file, const std::vector<std::string>& overrides);
// Parses TOML text (for tests); `what` names the source in errors.
Result<Config> parse_config(const std::string& toml_text, const std::string& what,
                            const std::vector<std::string>& overrides);
// The same config as TOML text that parse_config reads back equal (handed to the spawned server).
// With comments: each key is preceded by its documentation and unit (how config/default.toml is made).
std::string to_toml(const Config& config, bool with_comments = false);

// Why `name` cannot name a POSIX shared-memory segment (a file in /dev/shm: no '/', not "." or "..", at most
// NAME_MAX = 255 bytes, not empty), or nullopt if it can. protocol.segment_name and texstream-server
// --segment are checked with it, so that a bad name is refused naming the key (before, the renderer failed
// with "Invalid argument" and a standalone server waited for ever for a segment that could never exist).
std::optional<std::string> segment_name_problem(std::string_view name);
// Markdown table of every key: name, type, unit, default, range, meaning.
std::string config_reference_markdown();

}  // namespace texstream
