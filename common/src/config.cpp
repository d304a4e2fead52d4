#include "texstream/common/config.hpp"

#include <toml++/toml.h>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <variant>

namespace texstream {

namespace {

struct Range {
  double min;
  double max;
};
constexpr Range kAny{-1e300, 1e300};

// One declaration per key. Visitors: parse, apply override, print TOML, print docs. For a key whose type is
// a ConfigChoice enum, `doc` is a lead-in and its table's names and docs follow it (key_doc).
template <class V>
void visit_keys(Config& c, V&& v) {
  v("scene", "dir", c.scene.dir, "path",
    "Scene folder written by texstream-gen (relative paths are from the working directory)", kAny);

  v("protocol", "segment_name", c.protocol.segment_name, "name",
    "POSIX shared-memory name (a file in /dev/shm: no '/', at most 255 bytes); empty: texstream-<renderer pid>", kAny);
  v("protocol", "request_ring_capacity", c.protocol.request_ring_capacity, "records",
    "Request ring size (power of two)", Range{4, 65536});
  v("protocol", "completion_ring_capacity", c.protocol.completion_ring_capacity, "records",
    "Completion ring size (power of two)", Range{4, 65536});
  v("protocol", "staging_slot_count", c.protocol.staging_slot_count, "slots",
    "Staging slots: bound the mips in flight between the processes", Range{1, 16384});
  v("protocol", "staging_slot_bytes", c.protocol.staging_slot_bytes, "bytes",
    "Bytes per staging slot; a level larger than a slot is never loaded. 0 = the scene's largest mip (at least "
    "64 KiB; the slot count is then lowered to keep the pool within 512 MiB)",
    Range{0, 64 << 20});
  v("protocol", "heartbeat_timeout_ms", c.protocol.heartbeat_timeout_ms, "ms",
    "A peer whose progress heartbeat stalls this long is treated as hung", Range{10, 600000});

  v("server", "spawn", c.server.spawn, "bool",
    "Start texstream-server as a child; false: a standalone one (texstream-server --segment NAME) serves "
    "protocol.segment_name, and is not restarted by the renderer",
    kAny);
  v("server", "executable", c.server.executable, "path", "texstream-server binary; empty: next to texstream-render",
    kAny);
  v("server", "worker_threads", c.server.worker_threads, "threads",
    "Read/decode workers (default fits a 2-core machine)", Range{1, 64});
  v("server", "ram_cache_bytes", c.server.ram_cache_bytes, "bytes",
    "Byte budget of the server's RAM cache of mips, pre-faulted at start. With the staging pool and 64 MiB it must fit "
    "physical memory and any memory cgroup limit (else an error at start); more than is free now, less a reserve, is "
    "lowered with a warning",
    Range{0, 1ll << 40});
  v("server", "idle_wait_ms", c.server.idle_wait_ms, "ms", "Longest futex wait for new requests when idle",
    Range{0.1, 1000});
  v("server", "log_level", c.server.log_level, "level", "Log level of texstream-server:", kAny);
  v("server", "cache_policy", c.server.cache_policy, "name", "RAM cache eviction:", kAny);
  v("server", "rate_limit_mb_s", c.server.rate_limit_mb_s, "MB/s", "Cap on storage reads (0: unlimited), seed 002 §3.3",
    Range{0, 1e6});
  v("server", "remote_fetches_in_flight", c.server.remote_fetches_in_flight, "fetches",
    "Concurrent fetches from a remote or slow origin (threads; one connection each); RAM and disk-cache hits are "
    "served meanwhile. Seed 002 used 1; texstream-bench storage measured mips/s over a 20-30 ms origin rising from 1 "
    "to 8 (4: most of the gain, few threads and slots)",
    Range{1, 16});
  v("server", "batch_scheduling", c.server.batch_scheduling, "bool",
    "texstream-server's threads run SCHED_BATCH: woken by a request they wait for a tick instead of preempting the "
    "renderer's frame thread (the renderer's IPC per frame p99 halved on a 2-core VM; docs/design/syscalls.md). "
    "false: the ordinary policy",
    kAny);

  v("render", "device", c.render.device, "name", "Substring of the Vulkan device name to use; empty: the first device",
    kAny);
  v("render", "validation", c.render.validation, "bool", "Enable the Khronos validation layer", kAny);
  v("render", "window", c.render.window, "bool", "Open a GLFW window instead of rendering headless", kAny);
  v("render", "width_px", c.render.width_px, "px", "Framebuffer width", Range{16, 16384});
  v("render", "height_px", c.render.height_px, "px", "Framebuffer height", Range{16, 16384});
  v("render", "frames", c.render.frames, "frames", "Headless: frames to render; 0 = the whole camera path",
    Range{0, 1e9});
  v("render", "frame_time_ms", c.render.frame_time_ms, "ms", "Virtual time per frame along the camera path",
    Range{0.01, 10000});
  v("render", "lockstep", c.render.lockstep, "bool",
    "Each frame first takes every answer to the previous streaming cycle, so a run depends on the frame index only; a "
    "server death after the preload ends the run with an error (false: real time, never waits)",
    kAny);
  v("render", "pace_frames", c.render.pace_frames, "bool",
    "Real time: frame N starts no earlier than N x frame_time_ms after frame 0, like a display at 1000/frame_time_ms "
    "Hz, so a fast device does not fly the camera path faster than its speed (ignored in lock-step, with "
    "render.load_wanted_before_drawing and in window mode)",
    kAny);
  v("render", "camera_path", c.render.camera_path, "path", "Camera path file; empty: <scene>/camera_path.txt", kAny);
  v("render", "output_dir", c.render.output_dir, "path", "Folder for frames and the run summary", kAny);
  v("render", "write_every_frames", c.render.write_every_frames, "frames",
    "Write every Nth frame as PNG (0: only the last)", Range{0, 1e9});
  v("render", "fov_y_deg", c.render.fov_y_deg, "deg", "Vertical field of view of the viewport", Range{1, 170});
  v("render", "offscreen_fov_y_deg", c.render.offscreen_fov_y_deg, "deg",
    "Wider off-screen FOV whose meshes are requested at W = 1 (seed 000 §3.2)", Range{1, 170});
  v("render", "near_m", c.render.near_m, "m", "Near plane", Range{1e-3, 1e6});
  v("render", "far_m", c.render.far_m, "m", "Far plane", Range{1e-2, 1e8});
  v("render", "headlight_ambient", c.render.headlight_ambient, "fraction",
    "Headlight: camera-facing surfaces keep all their colour, edge-on ones this fraction (1 = unlit)", Range{0, 1});
  v("render", "debug_view", c.render.debug_view, "name", "What the frame shows instead of the textures:", kAny);
  v("render", "feedback", c.render.feedback, "bool",
    "Visibility metadata pass and compaction (off only to measure their cost)", kAny);
  v("render", "feedback_pairs", c.render.feedback_pairs, "bool",
    "Measurement of what feedback costs: each frame is drawn twice from the same pose, once as usual and once without "
    "feedback (the order alternates; new meshes' geometry is uploaded first, timed in neither; the twin uploads no "
    "mips and changes nothing the run shows), and the twin's latency goes to frames.csv's latency_off_ms "
    "(texstream-bench visibility; not with a window)",
    kAny);
  v("render", "preload_all", c.render.preload_all, "bool",
    "Before frame 0, load every mip of every texture through the server and wait (the cache must hold the scene): "
    "reference frames and the all-resident baseline",
    kAny);
  v("render", "blocking_loads", c.render.blocking_loads, "bool",
    "Blocking baseline (seed 002 §2): each frame loads the full mip chain of every texture the last visibility list "
    "named before drawing",
    kAny);
  v("render", "load_wanted_before_drawing", c.render.load_wanted_before_drawing, "bool",
    "Reference frames for a scene that cannot be resident at once: each frame is first drawn with feedback only "
    "(every mesh kept, tau = 0), then every mip it samples is loaded down to its wanted level (no load size, no "
    "bias) and only then is it drawn, so every pixel samples the levels a render.preload_all run samples "
    "(docs/design/reference_frames.md). The cache must hold one frame's mips (else the run ends naming "
    "cache.layers and cache.memory_bytes)",
    kAny);
  v("render", "reference_dir", c.render.reference_dir, "path",
    "Output folder of a reference run (render.preload_all or render.load_wanted_before_drawing) of the same path "
    "and size; non-empty: each frame's MSE, PSNR and SSIM against "
    "its frames/frame_NNNNN.png go to frames.csv",
    kAny);
  v("render", "staging_bytes", c.render.staging_bytes, "bytes", "Host-visible staging ring for uploads into the cache",
    Range{1 << 20, 1ll << 34});

  v("stream", "tau", c.stream.tau, "weight", "Mesh weight cutoff τ for compaction (seed 000 §3.3, Table 2)",
    Range{0, 1e12});
  v("stream", "max_anisotropy", c.stream.max_anisotropy, "ratio",
    "A_m for the mip-level metadata; sampling uses A_m/2 (seed 000 §3.2)", Range{1, 16});
  v("stream", "max_requests_in_flight", c.stream.max_requests_in_flight, "requests",
    "Requests outstanding at the server at once (pre-queue depth)", Range{1, 65536});
  v("stream", "max_mips_per_cycle", c.stream.max_mips_per_cycle, "mips", "Most mips requested in one streaming cycle",
    Range{1, 1e7});
  v("stream", "levels_in_flight", c.stream.levels_in_flight, "levels",
    "Most levels of one texture requested at once, each the next finer after what is resident or on its way "
    "(1: the seed's Algorithm 1, one level per texture per round trip)",
    Range{1, 16});
  v("stream", "colormap_blend", c.stream.colormap_blend, "bool",
    "Blend sampled colour with the City Colormap while finer mips arrive (false: sample directly)", kAny);
  v("stream", "blend", c.stream.blend, "name", "How the colormap is blended in:", kAny);
  v("stream", "blend_exponent", c.stream.blend_exponent, "power",
    "blend = converge: the colormap's share is (levels still missing / M_max) to this power (higher: less error "
    "while levels arrive, smaller steps hidden)",
    Range{1, 8});
  v("stream", "fade_ms", c.stream.fade_ms, "ms",
    "A newly resident finer level fades in from the one before it (a first level from the colormap) over this "
    "much path time; 0 shows it at once (render.load_wanted_before_drawing: always 0)",
    Range{0, 1e5});
  v("stream", "fade_when", c.stream.fade_when, "name", "When stream.fade_ms applies:", kAny);
  v("stream", "foreground_distance_m", c.stream.foreground_distance_m, "m",
    "Eq. 2 distance weight: w_d = (1 - min(depth / this, 1))^4 (the seed's c_w normalised to metres)",
    Range{1e-3, 1e7});

  v("controller", "mode", c.controller.mode, "name", "Load size s and mip bias b:", kAny);
  v("controller", "target_ms", c.controller.target_ms, "ms",
    "mode = auto: cap on the target frame latency (0: none; the target is 2x the measured latency without "
    "streaming, and a cap never brings it below 1.25x that)",
    Range{0, 3.6e6});
  v("controller", "target_min_ms", c.controller.target_min_ms, "ms",
    "mode = auto: the target is never below this (one 60 Hz refresh: a frame inside it is no stutter)",
    Range{0, 3.6e6});
  v("controller", "pace_share", c.controller.pace_share, "ratio",
    "mode = auto: the mips one frame takes in are paced so that its streaming work (measured per mip) stays "
    "within this share of the latency without streaming (0: no pacing)",
    Range{0, 100});
  v("controller", "alpha_ms", c.controller.alpha_ms, "ms",
    "mode = seed: α, target maximum frame latency (seed 000 Table 2)", Range{0.1, 10000});
  v("controller", "beta", c.controller.beta, "levels", "β: maximum mip bias (Table 2)", Range{0, 16});
  v("controller", "s_min_mb", c.controller.s_min_mb, "MB", "Minimum load size s_min (Table 2: one 64 KiB sparse block)",
    Range{0.001, 1e5});
  v("controller", "s_max_mb", c.controller.s_max_mb, "MB", "Maximum load size s_max (Table 2)", Range{0.001, 1e5});
  v("controller", "load_time_ms", c.controller.load_time_ms, "ms",
    "Longest time one streaming cycle may spend loading (Table 2)", Range{0.1, 1e6});
  v("controller", "fixed_load_mb", c.controller.fixed_load_mb, "MB", "mode = fixed: load size s", Range{0.001, 1e5});
  v("controller", "fixed_bias", c.controller.fixed_bias, "levels", "mode = fixed: mip bias b", Range{0, 16});
  v("pages", "enabled", c.pages.enabled, "bool",
    "Draw and stream the scene's ground as one huge texture in pages when scene.json has a \"ground\"", kAny);
  v("pages", "memory_bytes", c.pages.memory_bytes, "bytes",
    "GPU memory of the ground's page frames (one bordered page per array layer; never exceeded)",
    Range{1 << 20, 1ll << 40});
  v("pages", "per_frame", c.pages.per_frame, "pages", "Pages requested per frame at most (seed 004's page budget)",
    Range{1, 4096});
  v("pages", "heuristic", c.pages.heuristic, "name", "Which needed page goes first:", kAny);
  v("pages", "order", c.pages.order, "name", "When the ancestors of needed pages are loaded:", kAny);
  v("pages", "noise_scaling", c.pages.noise_scaling, "bool",
    "Priority times the NoiseValues between a page and its resident ancestor (seed 004 §4.2)", kAny);
  v("pages", "noise_skipping", c.pages.noise_skipping, "bool",
    "order = extern: ancestors whose NoiseValue is below the file's mean are not loaded (seed 004 §4.3)", kAny);
  v("pages", "locked_levels", c.pages.locked_levels, "levels",
    "The coarsest levels are never evicted (seed 004 §4.3.1 locks four)", Range{0, 16});
  v("pages", "discard", c.pages.discard, "name", "Which page leaves a full page cache:", kAny);
  v("pages", "needbuffer_step", c.pages.needbuffer_step, "px",
    "Every Nth pixel per axis writes the needbuffer (seed 004 renders it at reduced resolution)", Range{1, 64});
  v("pages", "reference", c.pages.reference, "bool",
    "Draw the ground from one ordinary mipmapped texture read whole from its page file (RGBA8, at most 8192 texels "
    "per side), nothing streamed: the reference the page path's seams are measured against",
    kAny);

  v("cache", "format", c.cache.format, "name", "Texel format of the GPU cache:", kAny);
  v("cache", "eviction", c.cache.eviction, "name", "Placement and eviction in the cache:", kAny);
  v("cache", "layer_extent_px", c.cache.layer_extent_px, "px",
    "Side of one cache layer (power of two), the largest texture extent it holds; 0 = chosen at start from the "
    "device's limits, the budget and the scene's largest texture (docs/design/cache_budget.md)",
    Range{0, 32768});
  v("cache", "layers", c.cache.layers, "layers",
    "Array layers of the sparse cache image; they cost address space only (lavapipe: 2 GiB), cache.memory_bytes "
    "bounds memory; 0 = up to 64x the budget, as the device's sparse address space allows",
    Range{0, 2048});
  v("cache", "memory_bytes", c.cache.memory_bytes, "bytes",
    "GPU memory for the cache's bound sparse pages (and mip tail); when full, cache.eviction decides what goes",
    Range{1 << 20, 1ll << 40});
  v("storage", "origin", c.storage.origin, "path/URL",
    "Where texture files come from: empty = scene.dir; a folder; or an http(s):// base URL (textures/... fetched with "
    "range requests)",
    kAny);
  v("storage", "disk_cache_dir", c.storage.disk_cache_dir, "path",
    "Disk cache of fetched ranges for a remote or slow origin (empty: none); one server per folder (flock)", kAny);
  v("storage", "disk_cache_bytes", c.storage.disk_cache_bytes, "bytes",
    "Disk space budget of the disk cache: each entry counts its file in whole blocks of the file system; lowered with "
    "a warning to what the file system can hold",
    Range{1 << 20, 1ll << 44});
  v("storage", "disk_cache_policy", c.storage.disk_cache_policy, "name", "Disk cache eviction:", kAny);
  v("storage", "connect_timeout_ms", c.storage.connect_timeout_ms, "ms", "http origin: connect timeout",
    Range{1, 600000});
  v("storage", "request_timeout_ms", c.storage.request_timeout_ms, "ms",
    "http origin: longest time for one range request", Range{1, 3600000});
  v("storage", "low_speed_bytes_s", c.storage.low_speed_bytes_s, "bytes/s",
    "http origin: a transfer slower than this for low_speed_time_s is aborted (slowloris stall); 0: off",
    Range{0, 1e12});
  v("storage", "low_speed_time_s", c.storage.low_speed_time_s, "s", "http origin: see low_speed_bytes_s",
    Range{1, 3600});
  v("storage", "retries", c.storage.retries, "attempts",
    "http origin: extra attempts after a transient failure (connect error, 5xx, timeout)", Range{0, 10});
  v("storage", "retry_backoff_ms", c.storage.retry_backoff_ms, "ms",
    "http origin: back-off before the first retry, doubled for each next one", Range{0, 60000});
  v("storage", "slow_enabled", c.storage.slow_enabled, "bool",
    "Wrap the origin in the slow-storage emulation (tests, benchmarks)", kAny);
  v("storage", "slow_latency_ms", c.storage.slow_latency_ms, "ms", "Slow storage: added latency per read",
    Range{0, 60000});
  v("storage", "slow_jitter_ms", c.storage.slow_jitter_ms, "ms",
    "Slow storage: uniform extra latency in [0, this) per read", Range{0, 60000});
  v("storage", "slow_bandwidth_mb_s", c.storage.slow_bandwidth_mb_s, "MB/s",
    "Slow storage: bandwidth cap shared by all reads (0: unlimited)", Range{0, 1e6});
  v("storage", "slow_stall_probability", c.storage.slow_stall_probability, "probability",
    "Slow storage: chance that a read stalls for slow_stall_ms", Range{0, 1});
  v("storage", "slow_stall_ms", c.storage.slow_stall_ms, "ms", "Slow storage: length of a stall", Range{0, 600000});
  v("storage", "slow_failure_rate", c.storage.slow_failure_rate, "probability",
    "Slow storage: chance that a read fails with an I/O error", Range{0, 1});
  v("storage", "slow_seed", c.storage.slow_seed, "seed",
    "Slow storage: seed of its random draws (same seed, same reads: same delays and failures)", Range{0, 9e15});
}

using Value = std::variant<bool, int64_t, double, std::string>;

std::string type_name(const bool&) { return "bool"; }
std::string type_name(const int64_t&) { return "integer"; }
std::string type_name(const double&) { return "float"; }
std::string type_name(const std::string&) { return "string"; }
template <ConfigChoice E>
std::string type_name(const E&) {
  return "string";
}

std::string format_value(const bool& b) { return b ? "true" : "false"; }
std::string format_value(const int64_t& i) { return std::to_string(i); }
std::string format_value(const double& d) {
  char buf[64];
  // Shortest text that reads back to the same double (so 33.333 stays 33.333).
  const auto res = std::to_chars(buf, buf + sizeof buf, d);
  std::string out(buf, res.ptr);
  if (out.find_first_of(".eEn") == std::string::npos) out += ".0";
  return out;
}
std::string format_value(const std::string& s) {
  std::string out = "\"";
  for (char ch : s) {
    const auto u = static_cast<unsigned char>(ch);
    if (u < 0x20 || u == 0x7f) {
      // TOML basic strings may not hold control characters raw (toml++ refuses to read them back): escape
      // them so that every value validate() accepts is written in a form that parses to the same value.
      char esc[8];
      std::snprintf(esc, sizeof esc, "\\u%04X", u);
      out += esc;
      continue;
    }
    if (ch == '"' || ch == '\\') out += '\\';
    out += ch;
  }
  return out + "\"";
}
template <ConfigChoice E>
std::string format_value(const E& value) {
  return format_value(std::string(choice_name(value)));
}

// The documentation of a key: for a choice, the lead-in and then every allowed name with what it does.
template <class T>
std::string key_doc(const T&, const char* doc) {
  if constexpr (ConfigChoice<T>) {
    return *doc ? std::string(doc) + " " + choice_docs<T>() : choice_docs<T>();
  } else {
    return doc;
  }
}

// toml++ as packaged by Debian throws on malformed input; turn that into a Result at the boundary.
Result<toml::table> parse_toml(const std::string& text, const std::string& what) {
  try {
    return toml::parse(text, what);
  } catch (const toml::parse_error& e) {
    return make_error(ErrorCode::kInvalidArgument,
                      what + ":" + std::to_string(e.source().begin.line) + ": " + std::string(e.description()));
  }
}

Error key_error(const std::string& what, const std::string& key, const std::string& msg) {
  return make_error(ErrorCode::kInvalidArgument, what + ": key '" + key + "': " + msg);
}

// Converts a TOML node to the field's type and range-checks it.
template <class T>
Status assign_from_node(T& field, const toml::node& node, const std::string& what, const std::string& key, Range r) {
  if constexpr (std::is_same_v<T, bool>) {
    auto v = node.value_exact<bool>();
    if (!v) return key_error(what, key, "expected a bool");
    field = *v;
  } else if constexpr (std::is_same_v<T, int64_t>) {
    auto v = node.value_exact<int64_t>();
    if (!v) return key_error(what, key, "expected an integer");
    if (static_cast<double>(*v) < r.min || static_cast<double>(*v) > r.max) {
      return key_error(what, key,
                       "value " + std::to_string(*v) + " outside [" + format_value(static_cast<int64_t>(r.min)) + ", " +
                           format_value(static_cast<int64_t>(r.max)) + "]");
    }
    field = *v;
  } else if constexpr (std::is_same_v<T, double>) {
    std::optional<double> v;
    if (node.is_floating_point())
      v = node.value_exact<double>();
    else if (node.is_integer())
      v = static_cast<double>(*node.value_exact<int64_t>());
    if (!v) return key_error(what, key, "expected a number");
    if (!std::isfinite(*v) || *v < r.min || *v > r.max) {
      return key_error(
          what, key,
          "value " + format_value(*v) + " outside [" + format_value(r.min) + ", " + format_value(r.max) + "]");
    }
    field = *v;
  } else if constexpr (ConfigChoice<T>) {
    auto v = node.value_exact<std::string>();
    if (!v) return key_error(what, key, "expected a string: " + choice_names<T>());
    std::optional<T> value = choice_from_name<T>(*v);
    if (!value) return key_error(what, key, "must be " + choice_names<T>() + ", not '" + *v + "'");
    field = *value;
  } else {
    auto v = node.value_exact<std::string>();
    if (!v) return key_error(what, key, "expected a string");
    field = *v;
  }
  return ok_status();
}

Status apply_table(Config& c, const toml::table& root, const std::string& what) {
  std::set<std::string> known_parts;
  std::set<std::string> known_keys;
  visit_keys(c, [&](const char* part, const char* key, auto&, const char*, const char*, Range) {
    known_parts.insert(part);
    known_keys.insert(std::string(part) + "." + key);
  });
  for (const auto& [part_key, part_node] : root) {
    const std::string part(part_key.str());
    if (!known_parts.count(part)) return key_error(what, part, "unknown section");
    const toml::table* t = part_node.as_table();
    if (!t) return key_error(what, part, "expected a [" + part + "] table");
    for (const auto& [k, node] : *t) {
      const std::string full = part + "." + std::string(k.str());
      if (!known_keys.count(full)) return key_error(what, full, "unknown key");
    }
  }
  Status status = ok_status();
  visit_keys(c, [&](const char* part, const char* key, auto& field, const char*, const char*, Range r) {
    if (!status.ok()) return;
    const toml::node* node = root.at_path(std::string(part) + "." + key).node();
    if (!node) return;
    status = assign_from_node(field, *node, what, std::string(part) + "." + key, r);
  });
  return status;
}

Status apply_override(Config& c, const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0) {
    return make_error(ErrorCode::kInvalidArgument, "--set '" + text + "': expected part.key=value");
  }
  const std::string key = text.substr(0, eq);
  const std::string value = text.substr(eq + 1);
  const auto dot = key.find('.');
  if (dot == std::string::npos) return key_error("--set", key, "expected part.key");
  // Let TOML parse the value so that "--set render.frames=10" and "--set scene.dir=x" both work: a bare
  // word that is not a TOML value is taken as a string.
  const std::string part = key.substr(0, dot), name = key.substr(dot + 1);
  bool is_string_key = false;
  visit_keys(c, [&](const char* p, const char* k, auto& field, const char*, const char*, Range) {
    using T = std::decay_t<decltype(field)>;
    if (std::string(p) + "." + k == key) is_string_key = std::is_same_v<T, std::string> || ConfigChoice<T>;
  });
  // A string or choice key takes the text as it is (so "--set scene.dir=x" needs no quotes); others are parsed
  // as TOML values so numbers and booleans keep their type.
  const std::string rhs = is_string_key && !(value.size() >= 2 && value.front() == '"') ? format_value(value) : value;
  auto parsed = parse_toml("[" + part + "]\n" + name + " = " + rhs + "\n", "--set " + key);
  if (!parsed.ok()) return key_error("--set", key, "cannot parse value '" + value + "'");
  return apply_table(c, parsed.value(), "--set");
}

bool is_pow2(int64_t v) { return v > 0 && (v & (v - 1)) == 0; }

}  // namespace

StagingShape effective_staging(const ProtocolConfig& protocol, uint64_t largest_mip_bytes, uint64_t shm_free_bytes) {
  constexpr uint64_t kMaxSlotBytes = 64ull << 20;  // the segment's limit (protocol/segment_layout.hpp)
  StagingShape s{static_cast<uint64_t>(protocol.staging_slot_count),
                 static_cast<uint64_t>(protocol.staging_slot_bytes)};
  if (s.slot_bytes != 0) return s;
  s.slot_bytes = std::clamp<uint64_t>((largest_mip_bytes + 4095) / 4096 * 4096, kMinAutoSlotBytes, kMaxSlotBytes);
  const uint64_t pool = std::min(kMaxAutoStagingBytes, shm_free_bytes / 2);
  s.slot_count = std::clamp<uint64_t>(pool / s.slot_bytes, std::min<uint64_t>(4, s.slot_count), s.slot_count);
  return s;
}

Status Config::validate() const {
  auto bad = [](const std::string& key, const std::string& msg) {
    return make_error(ErrorCode::kInvalidArgument, "config: key '" + key + "': " + msg);
  };
  if (!is_pow2(protocol.request_ring_capacity)) return bad("protocol.request_ring_capacity", "must be a power of two");
  if (!is_pow2(protocol.completion_ring_capacity))
    return bad("protocol.completion_ring_capacity", "must be a power of two");
  if (cache.layer_extent_px != 0 && !is_pow2(cache.layer_extent_px))
    return bad("cache.layer_extent_px", "must be 0 (auto) or a power of two");
  if (protocol.staging_slot_bytes != 0 && protocol.staging_slot_bytes < 4096)
    return bad("protocol.staging_slot_bytes", "must be 0 (auto) or at least 4096");
  if (render.staging_bytes < protocol.staging_slot_bytes) {
    return bad("render.staging_bytes", "must hold at least one staging slot (protocol.staging_slot_bytes)");
  }
  // The parser only ever stores a listed name; a config built in code could hold any cast integer.
  Status choices = ok_status();
  Config copy = *this;
  visit_keys(copy, [&](const char* part, const char* key, auto& field, const char*, const char*, Range) {
    using T = std::decay_t<decltype(field)>;
    if constexpr (ConfigChoice<T>) {
      if (choices.ok() && choice_name(field) == "?") {
        choices = bad(std::string(part) + "." + key,
                      "holds " + std::to_string(static_cast<int>(field)) + ", which is none of " + choice_names<T>());
      }
    }
  });
  TS_TRY(choices);
  if (controller.s_min_mb > controller.s_max_mb)
    return bad("controller.s_min_mb", "must not exceed controller.s_max_mb");
  if (render.near_m >= render.far_m) return bad("render.near_m", "must be less than render.far_m");
  if (render.offscreen_fov_y_deg < render.fov_y_deg) {
    return bad("render.offscreen_fov_y_deg", "must be at least render.fov_y_deg");
  }
  if (stream.max_requests_in_flight > protocol.request_ring_capacity) {
    return bad("stream.max_requests_in_flight", "must not exceed protocol.request_ring_capacity");
  }
  if (!protocol.segment_name.empty()) {
    if (std::optional<std::string> problem = segment_name_problem(protocol.segment_name)) {
      return bad("protocol.segment_name", *problem);
    }
  }
  if (!server.spawn && protocol.segment_name.empty()) {
    return bad("server.spawn", "false needs protocol.segment_name: the name the standalone texstream-server serves");
  }
  if (protocol.completion_ring_capacity < protocol.request_ring_capacity) {
    return bad("protocol.completion_ring_capacity",
               "must be at least protocol.request_ring_capacity (every request is answered)");
  }
  if (render.window && render.feedback_pairs) {
    return bad("render.feedback_pairs", "a measurement of headless runs; it cannot be used with render.window");
  }
  if (render.preload_all && render.blocking_loads) {
    return bad("render.preload_all", "and render.blocking_loads: choose one (both are baselines of their own)");
  }
  if (render.load_wanted_before_drawing) {
    const char* key = "render.load_wanted_before_drawing";
    if (render.preload_all) return bad(key, "and render.preload_all: choose one (both make reference frames)");
    if (render.blocking_loads) return bad(key, "and render.blocking_loads: choose one (each loads before drawing)");
    if (!render.feedback) return bad(key, "needs render.feedback = true: the frame's mips come from its feedback");
    if (render.feedback_pairs) return bad(key, "cannot be used with render.feedback_pairs (a real-time measurement)");
  }
  return ok_status();
}

std::optional<std::string> segment_name_problem(std::string_view name) {
  if (name.empty()) return "must not be empty";
  if (name.size() > 255) {
    return "is " + std::to_string(name.size()) + " bytes long; a shared-memory name has at most 255 (NAME_MAX)";
  }
  if (name.find('/') != std::string_view::npos)
    return "'" + std::string(name) + "' contains '/'; a shared-memory name cannot";
  if (name.find('\0') != std::string_view::npos) return "contains a NUL byte";
  if (name == "." || name == "..") return "cannot be '" + std::string(name) + "'";
  return std::nullopt;
}

Result<Config> parse_config(const std::string& toml_text, const std::string& what,
                            const std::vector<std::string>& overrides) {
  Config c;
  auto parsed = parse_toml(toml_text, what);
  if (!parsed.ok()) return parsed.error();
  TS_TRY(apply_table(c, parsed.value(), what));
  for (const auto& o : overrides) TS_TRY(apply_override(c, o));
  TS_TRY(c.validate());
  return c;
}

Result<Config> load_config(const std::filesystem::path& file, const std::vector<std::string>& overrides) {
  std::string text;
  if (!file.empty()) {
    std::ifstream in(file);
    if (!in) return make_error(ErrorCode::kNotFound, "config file '" + file.string() + "' cannot be read");
    std::ostringstream ss;
    ss << in.rdbuf();
    text = ss.str();
  }
  return parse_config(text, file.empty() ? std::string("<defaults>") : file.string(), overrides);
}

std::string to_toml(const Config& config, bool with_comments) {
  Config c = config;
  std::map<std::string, std::string> parts;
  std::vector<std::string> order;
  visit_keys(c, [&](const char* part, const char* key, auto& field, const char* unit, const char* doc, Range) {
    if (!parts.count(part)) order.push_back(part);
    if (with_comments) parts[part] += "# " + key_doc(field, doc) + " [" + unit + "]\n";
    parts[part] += std::string(key) + " = " + format_value(field) + "\n";
  });
  std::string out;
  for (const auto& p : order) out += "[" + p + "]\n" + parts[p] + "\n";
  return out;
}

std::string config_reference_markdown() {
  Config c;
  std::string out = "| key | type | unit | default | range | meaning |\n|---|---|---|---|---|---|\n";
  visit_keys(c, [&](const char* part, const char* key, auto& field, const char* unit, const char* doc, Range r) {
    std::string range = "—";
    using T = std::decay_t<decltype(field)>;
    if constexpr (std::is_same_v<T, int64_t>) {
      if (r.min > -1e299)
        range = std::to_string(static_cast<int64_t>(r.min)) + " … " + std::to_string(static_cast<int64_t>(r.max));
    } else if constexpr (std::is_same_v<T, double>) {
      if (r.min > -1e299) range = format_value(r.min) + " … " + format_value(r.max);
    } else if constexpr (ConfigChoice<T>) {
      range = choice_names<T>();
    }
    std::string def = format_value(field);
    out += "| `" + std::string(part) + "." + key + "` | " + type_name(field) + " | " + unit + " | `" + def + "` | " +
           range + " | " + key_doc(field, doc) + " |\n";
  });
  return out;
}

}  // namespace texstream
