// texstream-bench storage [--quick] [--out DIR]
//
// Remote and slow storage (issue 4, seed 002 §3.2-3.3 and Fig. 12-13). Starts its own nginx on loopback
// (config/nginx/texstream-origin.conf.in) serving a generated rgba8 scene, runs the texture server in this
// process against it (the bench plays the renderer), stops nginx again. Measures:
//   1. hit_p99_ratio_under_load: RAM-hit latency p99 while every remote-fetch worker is busy with a slow
//      (ISDN-limited) fetch and more misses wait for them, over the idle hit p99. Goal ≤ 2.
//   2. disk_cache_reuse: a second server on the same disk cache replays the same requests: fraction of its
//      bytes from the disk cache. Goal ≥ 0.95.
//   3. Fig. 12 redone without the image-error metric (issue 8 lands it): bytes/s, mips/s and time to first mip
//      of the full scene streamed coarsest first through nginx at unlimited, 10 MB/s, 1.5 Mbit/s (T1) and
//      128 kbit/s (ISDN), one connection (server.remote_fetches_in_flight = 1: one link, since nginx's
//      limit_rate is per connection). CSVs: storage_bandwidth.csv (one row per link), storage_timeline.csv
//      (cumulative bytes and mips over time, per link: the plot).
//   4. Disk-cache LRU vs FIFO (seed 002's) byte hit rates on a moving-window trace with popular landmarks.
//   5. remote_fetches_in_flight 1 vs 2 vs 4 vs 8 over a latency-bound slow origin (emulated: 20 ms ± 10 ms per
//      read, 8 MB/s shared link): mips/s.
//   6. failures_handled=N/M: origin down, 404, 500, truncated body, wrong Content-Range, slowloris stall: an
//      error completion within its deadline and the server still answering.
//   7. Fig. 12 with the image-error metric (storage_fig12.hpp): texstream-render over a fixed camera path with
//      its server reading the scene through nginx at the same four link rates (a true shared cap: the
//      slow-storage token bucket over nginx's unthrottled prefix), against reference frames: ∫MSE dt, mean
//      PSNR, bytes and mips per second, time to first mip. storage_fig12.csv, storage_fig12_frames.csv;
//      storage_plots.py draws storage_fig12.png and storage_timeline.png.
#include <sys/stat.h>
#include <unistd.h>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "bench_registry.hpp"
#include "bench_util.hpp"
#include "fake_http_origin.hpp"
#include "nginx_origin.hpp"
#include "path_runner.hpp"
#include "server_harness.hpp"
#include "storage_fig12.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/server/storage/disk_cache.hpp"
#include "texstream/server/storage/storage_stack.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;

namespace texstream::bench {
namespace {

using test::DriveResult;
using test::ServerHarness;
using test::WantedMip;

struct Plan {
  bool quick = false;
  fs::path out = "out/bench-storage";
  fs::path work;  // scene, nginx, caches (removed at the end)
  fs::path scene;
  uint32_t textures = 0;
  std::chrono::milliseconds link_run{0};  // time cap of one bandwidth run
  // --phases hits,reuse,links,policies,inflight,failures,fig12: run only these (profiling one); skipped ones
  // report 0.
  std::string phases = "hits,reuse,links,policies,inflight,failures,fig12";
  bool runs(const char* phase) const {
    return ("," + phases + ",").find(std::string(",") + phase + ",") != std::string::npos;
  }
};

std::vector<WantedMip> coarsest_first(const std::vector<scene::TextureRecord>& table, uint32_t first_texture,
                                      uint32_t count) {
  // Algorithm 1's order across the scene: every texture's coarsest mip before any texture's next finer one.
  std::vector<WantedMip> w;
  uint32_t max_mips = 0;
  for (const auto& t : table) max_mips = std::max(max_mips, t.mip_count);
  for (uint32_t depth = 0; depth < max_mips; ++depth) {
    for (uint32_t t = first_texture; t < std::min<uint32_t>(first_texture + count, uint32_t(table.size())); ++t) {
      if (depth >= table[t].mip_count) continue;
      const uint32_t mip = table[t].mip_count - 1 - depth;
      w.push_back({t, mip, float(max_mips - depth)});
    }
  }
  return w;
}

StorageConfig http_storage(const std::string& origin) {
  StorageConfig c;
  c.origin = origin;
  c.connect_timeout_ms = 500;
  c.request_timeout_ms = 30000;  // an ISDN fetch of a 256 KiB mip takes 16 s
  c.low_speed_bytes_s = 1024;
  c.low_speed_time_s = 2;
  c.retries = 1;
  c.retry_backoff_ms = 20;
  return c;
}

ServerConfig server_config(int64_t remote_fetches) {
  ServerConfig s;
  s.remote_fetches_in_flight = remote_fetches;
  s.log_level = LogLevel::kWarn;
  return s;
}

struct Stack {
  std::unique_ptr<server::StorageStack> storage;
  std::unique_ptr<ServerHarness> harness;
};

std::optional<Stack> start(const Plan& plan, const StorageConfig& storage, const ServerConfig& server) {
  auto s = server::make_storage_stack(storage, plan.scene);
  if (!s.ok()) {
    std::fprintf(stderr, "storage bench: %s\n", s.error().message.c_str());
    return std::nullopt;
  }
  Stack st;
  st.storage = std::move(s).value();
  std::string error;
  st.harness = ServerHarness::start(st.storage->scene_dir, server, st.storage->storage(), error);
  if (!st.harness) {
    std::fprintf(stderr, "storage bench: %s\n", error.c_str());
    return std::nullopt;
  }
  return st;
}

double now_us() {
  return std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// ---------------------------------------------------------------------------------------------------------
// 1. Hit latency with the remote-fetch workers saturated.
struct HitLatency {
  double idle_p50_us = 0, idle_p99_us = 0, loaded_p50_us = 0, loaded_p99_us = 0;
  uint64_t remote_fetches = 0, unfilled = 0, loads_ok = 0;
};

HitLatency measure_hit_latency(const Plan& plan, const test::NginxOrigin& nginx,
                               const std::vector<scene::TextureRecord>& table) {
  HitLatency out;
  constexpr int64_t kRemote = 4;  // the default server.remote_fetches_in_flight
  // Two servers on the same ISDN origin, measured in alternating rounds so that whatever else the 2-core
  // machine does at the time weighs on both alike: `idle` only serves hits, `loaded` has every remote-fetch
  // worker busy with a large mip (after nginx's one-second allowance of 16 kB it trickles for seconds: busy
  // but asleep, as with a real far origin) and more misses waiting for them.
  auto idle_st = start(plan, http_storage(nginx.url("isdn")), server_config(kRemote));
  auto loaded_st = start(plan, http_storage(nginx.url("isdn")), server_config(kRemote));
  if (!idle_st || !loaded_st) return out;
  // Hit set: the coarse half of the first quarter's textures (small mips: they arrive quickly).
  const uint32_t hit_textures = std::max<uint32_t>(4, plan.textures / 4);
  std::vector<WantedMip> hit_set;
  for (uint32_t t = 0; t < hit_textures; ++t) {
    for (uint32_t m = table[t].mip_count / 2; m < table[t].mip_count; ++m) hit_set.push_back({t, m, 1.0f});
  }
  for (ServerHarness* h : {idle_st->harness.get(), loaded_st->harness.get()}) {
    const DriveResult warm = test::drive(*h, hit_set, 60s);
    if (!warm.complete || warm.ok != hit_set.size()) {
      std::fprintf(stderr, "storage bench: warming the hit set: %llu of %zu mips\n", (unsigned long long)warm.ok,
                   hit_set.size());
    }
  }
  // Misses for the loaded server: every mip of the other textures, largest first, each asked once (a
  // fetched mip would turn into a RAM hit).
  std::vector<WantedMip> misses;
  for (uint32_t t = hit_textures; t < table.size(); ++t) {
    for (uint32_t m = 0; m < table[t].mip_count; ++m) misses.push_back({t, m, 0.5f});
  }
  auto bytes_of = [&](const WantedMip& w) {
    return mip_bytes(static_cast<TexelFormat>(table[w.texture].format), table[w.texture].width, table[w.texture].height,
                     w.mip);
  };
  std::sort(misses.begin(), misses.end(),
            [&](const WantedMip& x, const WantedMip& y) { return bytes_of(x) > bytes_of(y); });
  // Only mips that take seconds at ISDN (2 s or more of its 16 kB/s after the first second's allowance), so the
  // workers stay busy for the whole measurement instead of running through small mips.
  constexpr uint64_t kSlowMipBytes = 3 * 16000;
  const auto slow_end =
      std::find_if(misses.begin(), misses.end(), [&](const WantedMip& w) { return bytes_of(w) < kSlowMipBytes; });
  if (slow_end - misses.begin() >= kRemote + 2) misses.erase(slow_end, misses.end());
  size_t next_miss = 0;
  uint32_t misses_out = 0;
  constexpr uint64_t kGeneration = 1000;  // one cycle throughout: waiting misses are never superseded
  // One pass of `samples` hits, one outstanding at a time; `loaded` tops the misses up first.
  auto pass = [&](ServerHarness& h, bool loaded, int samples, std::vector<double>* latencies) {
    for (int i = 0; i < samples; ++i) {
      if (loaded) {
        while (misses_out < kRemote + 2 && next_miss < misses.size()) {
          const WantedMip& m = misses[next_miss];
          if (!h.push(m.texture, m.mip, kGeneration, m.priority)) break;
          ++next_miss;
          ++misses_out;
        }
      }
      const WantedMip& want = hit_set[size_t(i) % hit_set.size()];
      const double t0 = now_us();
      if (!h.push(want.texture, want.mip, kGeneration, 2.0f)) continue;
      h.ring();
      bool done = false;
      while (!done) {
        h.poll([&](const CompletionRecord& c, std::span<const std::byte>) {
          if (c.texture_id == want.texture && c.mip_level == want.mip) {
            done = true;
            if (latencies && c.status == uint32_t(CompletionStatus::kOk)) latencies->push_back(now_us() - t0);
          } else {
            --misses_out;
            if (c.status == uint32_t(CompletionStatus::kOk)) ++out.loads_ok;
          }
        });
      }
    }
  };
  ServerHarness& idle_h = *idle_st->harness;
  ServerHarness& loaded_h = *loaded_st->harness;
  pass(idle_h, false, int(hit_set.size()) * 2, nullptr);  // untimed: warm code paths
  pass(loaded_h, true, int(hit_set.size()) * 2, nullptr);
  const uint64_t fetches_before = loaded_h.server().remote_fetches();
  const int rounds = 10, per_round = plan.quick ? 200 : 800;
  std::vector<double> idle, loaded;
  for (int r = 0; r < rounds; ++r) {
    pass(idle_h, false, per_round, &idle);
    pass(loaded_h, true, per_round, &loaded);
  }
  out.remote_fetches = loaded_h.server().remote_fetches() - fetches_before + kRemote;
  out.unfilled = loaded_h.server().unfilled();
  out.idle_p50_us = percentile(idle, 50);
  out.idle_p99_us = percentile(idle, 99);
  out.loaded_p50_us = percentile(loaded, 50);
  out.loaded_p99_us = percentile(loaded, 99);
  // Misses still out are cut short when the stacks go (cancel_all).
  return out;
}

// ---------------------------------------------------------------------------------------------------------
// 2. Disk-cache reuse across a restart.
struct Reuse {
  double reuse = 0;
  uint64_t first_origin_bytes = 0, second_disk_bytes = 0, second_origin_bytes = 0;
  double first_s = 0, second_s = 0;
  bool complete = false;
};

Reuse measure_reuse(const Plan& plan, const test::NginxOrigin& nginx, const std::vector<scene::TextureRecord>& table) {
  Reuse r;
  StorageConfig c = http_storage(nginx.url("unlimited"));
  c.disk_cache_dir = (plan.work / "cache_reuse").string();
  const std::vector<WantedMip> wanted = coarsest_first(table, 0, uint32_t(table.size()));
  {
    auto st = start(plan, c, server_config(ServerConfig{}.remote_fetches_in_flight));
    if (!st) return r;
    const DriveResult d = test::drive(*st->harness, wanted, 60s);
    r.first_s = d.seconds;
    r.first_origin_bytes = st->storage->caching->counters().bytes_from_origin.load();
  }
  auto st = start(plan, c, server_config(ServerConfig{}.remote_fetches_in_flight));
  if (!st) return r;
  const DriveResult d = test::drive(*st->harness, wanted, 60s);
  r.complete = d.complete && d.ok == wanted.size();
  r.second_s = d.seconds;
  r.second_disk_bytes = st->storage->caching->counters().bytes_from_disk_cache.load();
  r.second_origin_bytes = st->storage->caching->counters().bytes_from_origin.load();
  const double total = double(r.second_disk_bytes + r.second_origin_bytes);
  r.reuse = total > 0 ? double(r.second_disk_bytes) / total : 0;
  return r;
}

// ---------------------------------------------------------------------------------------------------------
// 3. Bandwidth runs through nginx limit_rate.
struct Link {
  const char* name;
  const char* location;
  double nominal_bytes_s;  // 0: unlimited
};
constexpr Link kLinks[] = {{"unlimited", "unlimited", 0},
                           {"10MB_s", "mb10", 10e6},
                           {"T1_1.5Mbit_s", "t1", 1.5e6 / 8},
                           {"ISDN_128kbit_s", "isdn", 128e3 / 8}};

struct LinkRun {
  DriveResult drive;
  double mb_s = 0, mips_s = 0;
  std::vector<test::TimelinePoint> timeline;
};

// `emulated`: nginx unlimited behind the slow-storage emulation's shared token bucket at the link's nominal
// rate (a true link cap: nginx's limit_rate grants each response one second of its rate up front).
LinkRun run_link(const Plan& plan, const test::NginxOrigin& nginx, const Link& link,
                 const std::vector<scene::TextureRecord>& table, bool emulated = false) {
  LinkRun r;
  StorageConfig c = http_storage(nginx.url(emulated ? "unlimited" : link.location));
  if (emulated) {
    c.slow_enabled = true;
    c.slow_bandwidth_mb_s = link.nominal_bytes_s / 1e6;
  }
  auto st = start(plan, c, server_config(1));
  if (!st) return r;
  const std::vector<WantedMip> wanted = coarsest_first(table, 0, uint32_t(table.size()));
  // The renderer's defaults: 256 requests outstanding (stream.max_requests_in_flight), a cycle per 16 ms frame.
  r.drive = test::drive(*st->harness, wanted, plan.link_run, 256, 16ms, &r.timeline);
  const double s = std::max(r.drive.seconds, 1e-6);
  r.mb_s = double(r.drive.bytes) / s / 1e6;
  r.mips_s = double(r.drive.ok) / s;
  return r;
}

// ---------------------------------------------------------------------------------------------------------
// 4. LRU vs FIFO on a trace, through the real DiskCache.
struct PolicyRates {
  double lru = 0, fifo = 0;
  uint64_t accesses = 0;
};

PolicyRates compare_policies(const Plan& plan, const std::vector<scene::TextureRecord>& table) {
  // A camera moving along the city: each step sees a window of textures that slides by `step`, plus a few
  // landmarks visible from everywhere (popular: Zipf-like). Mips: the visible textures' finer mips nearer
  // the camera (centre of the window). Same trace for both policies, budget 30% of the disk space of the trace's unique
  // entries.
  const uint32_t n = uint32_t(table.size());
  const uint32_t window = std::max<uint32_t>(8, n / 6), step = std::max<uint32_t>(1, window / 8);
  const uint32_t steps = plan.quick ? 200 : 800;
  std::mt19937 rng(42);
  struct Access {
    std::string key;
    uint64_t bytes;
  };
  std::vector<Access> trace;
  auto add = [&](uint32_t t, uint32_t mip) {
    const auto& rec = table[t];
    const uint64_t b = mip_bytes(static_cast<TexelFormat>(rec.format), rec.width, rec.height, mip);
    trace.push_back({server::DiskCache::key_of(fmt::format("textures/{}.dds", t), mip, b), b});
  };
  // The camera goes back and forth along the street (a triangle wave over the texture ids, period 40 steps),
  // so what it saw comes back into view: the case where keeping recently used entries should pay.
  const uint32_t span = n > window ? n - window : 1;
  for (uint32_t s = 0; s < steps; ++s) {
    const uint32_t phase = s % 40, pos = (phase < 20 ? phase : 40 - phase) * step;
    const uint32_t start = std::min(pos, span);
    for (uint32_t i = 0; i < window; ++i) {
      const uint32_t t = (start + i) % n;
      const uint32_t distance = std::min(i, window - 1 - i);  // 0 at the window's ends, largest mid-window
      const uint32_t finest = table[t].mip_count > 1 + distance / 2 ? 0 : table[t].mip_count - 1;
      add(t, std::min(table[t].mip_count - 1, finest + (window / 2 - std::min(distance, window / 2)) / 3));
    }
    for (int l = 0; l < 3; ++l) {  // landmarks: textures 0..7, the lower ids far more often
      const uint32_t t = std::min<uint32_t>(n - 1, uint32_t(std::geometric_distribution<int>(0.5)(rng)) % 8);
      add(t, 0);
    }
  }
  std::unordered_map<std::string, uint64_t> unique;
  for (const Access& a : trace) unique[a.key] = a.bytes;
  // The disk space the trace's entries take (the budget counts each entry's file in whole blocks).
  uint64_t unique_bytes = 0;
  const fs::path probe = plan.work / "trace_probe";
  {
    auto cache = server::DiskCache::open(probe, 1, server::DiskCachePolicy::kLru);
    for (const auto& [k, b] : unique) unique_bytes += cache.ok() ? (*cache)->footprint(k, b) : b;
  }
  fs::remove_all(probe);
  PolicyRates out;
  out.accesses = trace.size();
  for (auto policy : {server::DiskCachePolicy::kLru, server::DiskCachePolicy::kFifo}) {
    const fs::path dir = plan.work / (policy == server::DiskCachePolicy::kLru ? "trace_lru" : "trace_fifo");
    auto cache = server::DiskCache::open(dir, std::max<uint64_t>(1, unique_bytes * 3 / 10), policy);
    if (!cache.ok()) continue;
    uint64_t hit = 0, total = 0;
    std::vector<std::byte> buf;
    for (const Access& a : trace) {
      buf.assign(a.bytes, std::byte{0x5a});
      total += a.bytes;
      if (std::optional<uint64_t> got = (*cache)->read(a.key, buf)) {
        hit += *got;
      } else {
        (*cache)->insert(a.key, buf);
      }
    }
    (policy == server::DiskCachePolicy::kLru ? out.lru : out.fifo) = total ? double(hit) / double(total) : 0;
  }
  return out;
}

// ---------------------------------------------------------------------------------------------------------
// 5. Remote fetches in flight 1, 2, 4 over an emulated latency-bound origin.
struct InFlightRun {
  int64_t fetches;
  double mips_s;
  double mb_s;
};

InFlightRun run_in_flight(const Plan& plan, int64_t fetches, const std::vector<scene::TextureRecord>& table) {
  StorageConfig c;
  c.slow_enabled = true;
  c.slow_latency_ms = 20;  // a WAN round trip
  c.slow_jitter_ms = 10;
  c.slow_bandwidth_mb_s = 8;
  c.slow_seed = 7;
  InFlightRun r{fetches, 0, 0};
  auto st = start(plan, c, server_config(fetches));
  if (!st) return r;
  const DriveResult d = test::drive(*st->harness, coarsest_first(table, 0, uint32_t(table.size())),
                                    plan.quick ? 2000ms : 8000ms, 256, 16ms);
  r.mips_s = double(d.ok) / std::max(d.seconds, 1e-6);
  r.mb_s = double(d.bytes) / std::max(d.seconds, 1e-6) / 1e6;
  return r;
}

// ---------------------------------------------------------------------------------------------------------
// 6. Origin failures.
struct Failure {
  const char* name;
  bool handled = false;
  double ms = 0;
  uint32_t status = 0;
};

Failure run_failure(const Plan& plan, const char* name, const StorageConfig& c, std::chrono::milliseconds deadline) {
  Failure f{name};
  auto st = start(plan, c, server_config(ServerConfig{}.remote_fetches_in_flight));
  if (!st) return f;
  const DriveResult d = test::drive(*st->harness, {{0, 0, 1.0f}}, deadline + 2s);
  f.ms = d.seconds * 1000;
  f.status = d.status[0];
  // Handled: an error completion (not kOk, not silence) before the deadline, and the server answers the next
  // request too (the renderer keeps drawing).
  const DriveResult again = test::drive(*st->harness, {{1, 0, 1.0f}}, deadline + 2s);
  f.handled = d.complete && d.status[0] != uint32_t(CompletionStatus::kOk) &&
              d.seconds * 1000 < double(deadline.count()) && again.complete;
  return f;
}

int run_storage(Plan plan) {
  spdlog::set_level(spdlog::level::err);  // expected failures (phase 6) would flood the output
  Stopwatch total;
  plan.textures = plan.quick ? 48 : 192;
  plan.link_run = plan.quick ? 2500ms : 20000ms;
  plan.work = fs::temp_directory_path() / fmt::format("texstream-bench-storage-{}", ::getpid());
  fs::remove_all(plan.work);
  fs::create_directories(plan.work);
  std::error_code ec;
  fs::create_directories(plan.out, ec);
  if (ec) {
    std::fprintf(stderr, "storage bench: --out %s: %s\n", plan.out.c_str(), ec.message().c_str());
    return 2;
  }
  plan.scene = plan.work / "scene";
  const fs::path bin = fs::read_symlink("/proc/self/exe").parent_path();
  const std::string gen = fmt::format("'{}' --out '{}' --textures {} --seed 5 --format rgba8 --threads 2 > /dev/null",
                                      (bin / "texstream-gen").string(), plan.scene.string(), plan.textures);
  if (std::system(gen.c_str()) != 0) {
    std::fprintf(stderr, "storage bench: %s failed\n", gen.c_str());
    return 1;
  }
  auto table = scene::read_texture_table(plan.scene);
  if (!table.ok()) {
    std::fprintf(stderr, "storage bench: %s\n", table.error().message.c_str());
    return 1;
  }
  uint64_t scene_bytes = 0;
  for (const auto& t : *table) {
    scene_bytes += mip_chain_offset(static_cast<TexelFormat>(t.format), t.width, t.height, t.mip_count);
  }
  std::string error;
  auto nginx = test::NginxOrigin::start(
      plan.scene, fs::path(TEXSTREAM_STORAGE_BENCH_SOURCE_DIR) / "config/nginx/texstream-origin.conf.in",
      plan.work / "nginx", error);
  if (!nginx) {
    std::fprintf(stderr, "storage bench: %s\n", error.c_str());
    return 1;
  }
  std::printf("storage bench (%s): %u rgba8 textures, %.2f MB of mips, nginx on 127.0.0.1:%u\n",
              plan.quick ? "quick" : "full", plan.textures, double(scene_bytes) / 1e6, nginx->port());

  const HitLatency hits = plan.runs("hits") ? measure_hit_latency(plan, *nginx, *table) : HitLatency{};
  const double hit_ratio = hits.idle_p99_us > 0 ? hits.loaded_p99_us / hits.idle_p99_us : 0;
  std::printf(
      "1. RAM hits: idle p50 %.1f us p99 %.1f us; with the remote workers saturated through ISDN p50 %.1f us "
      "p99 %.1f us (ratio %.2f; ~%llu remote fetches busy or started, %llu unfilled, %llu slow loads done meanwhile)\n",
      hits.idle_p50_us, hits.idle_p99_us, hits.loaded_p50_us, hits.loaded_p99_us, hit_ratio,
      (unsigned long long)hits.remote_fetches, (unsigned long long)hits.unfilled, (unsigned long long)hits.loads_ok);

  const Reuse reuse = plan.runs("reuse") ? measure_reuse(plan, *nginx, *table) : Reuse{};
  std::printf(
      "2. disk cache: first run %.2f s, %.2f MB from the origin; second run (new server, same folder) %.2f s, "
      "%.2f MB from the disk cache, %.2f MB from the origin: reuse %.4f%s\n",
      reuse.first_s, double(reuse.first_origin_bytes) / 1e6, reuse.second_s, double(reuse.second_disk_bytes) / 1e6,
      double(reuse.second_origin_bytes) / 1e6, reuse.reuse, reuse.complete ? "" : " (INCOMPLETE)");

  std::ofstream csv(plan.out / "storage_bandwidth.csv");
  csv << "link,nominal_bytes_s,seconds,mips,bytes,mb_s,mips_s,first_mip_ms,complete\n";
  std::ofstream timeline(plan.out / "storage_timeline.csv");
  timeline << "link,seconds,bytes,mips\n";
  double t1_mb_s = 0, isdn_mb_s = 0;
  std::printf("3. streaming the scene coarsest first through nginx limit_rate (one connection, %.1f s cap):\n",
              double(plan.link_run.count()) / 1000);
  for (const Link& link : kLinks) {
    if (!plan.runs("links")) break;
    const LinkRun r = run_link(plan, *nginx, link, *table);
    std::printf("   %-24s %8.3f MB/s %8.1f mips/s  first mip %7.2f ms  %llu mips, %.2f MB in %.2f s%s\n", link.name,
                r.mb_s, r.mips_s, r.drive.first_ok_s * 1000, (unsigned long long)r.drive.ok,
                double(r.drive.bytes) / 1e6, r.drive.seconds, r.drive.complete ? " (all)" : "");
    csv << fmt::format("{},{},{:.4f},{},{},{:.6f},{:.3f},{:.3f},{}\n", link.name, link.nominal_bytes_s, r.drive.seconds,
                       r.drive.ok, r.drive.bytes, r.mb_s, r.mips_s, r.drive.first_ok_s * 1000,
                       r.drive.complete ? 1 : 0);
    for (const auto& p : r.timeline)
      timeline << fmt::format("{},{:.4f},{},{}\n", link.name, p.seconds, p.bytes, p.mips);
    if (std::string(link.location) == "t1") t1_mb_s = r.mb_s;
    if (std::string(link.location) == "isdn") isdn_mb_s = r.mb_s;
  }
  std::printf(
      "   the same links as a true shared cap (nginx unlimited + slow-storage token bucket at the nominal rate):\n");
  for (const Link& link : kLinks) {
    if (!plan.runs("links")) break;
    if (link.nominal_bytes_s == 0) continue;
    const LinkRun r = run_link(plan, *nginx, link, *table, true);
    const std::string name = std::string(link.name) + "_emulated";
    std::printf("   %-24s %8.3f MB/s %8.1f mips/s  first mip %7.2f ms  %llu mips, %.2f MB in %.2f s%s\n", name.c_str(),
                r.mb_s, r.mips_s, r.drive.first_ok_s * 1000, (unsigned long long)r.drive.ok,
                double(r.drive.bytes) / 1e6, r.drive.seconds, r.drive.complete ? " (all)" : "");
    csv << fmt::format("{},{},{:.4f},{},{},{:.6f},{:.3f},{:.3f},{}\n", name, link.nominal_bytes_s, r.drive.seconds,
                       r.drive.ok, r.drive.bytes, r.mb_s, r.mips_s, r.drive.first_ok_s * 1000,
                       r.drive.complete ? 1 : 0);
    for (const auto& p : r.timeline) timeline << fmt::format("{},{:.4f},{},{}\n", name, p.seconds, p.bytes, p.mips);
  }

  const PolicyRates rates = plan.runs("policies") ? compare_policies(plan, *table) : PolicyRates{};
  std::printf(
      "4. disk cache on a moving-window trace (%llu accesses, budget 30%% of its entries' disk space): byte hit rate "
      "LRU %.4f, FIFO %.4f\n",
      (unsigned long long)rates.accesses, rates.lru, rates.fifo);

  std::printf("5. remote fetches in flight over an emulated WAN origin (20 ms + 0-10 ms per read, 8 MB/s):\n");
  std::vector<InFlightRun> in_flight;
  for (int64_t n : {1, 2, 4, 8}) {
    if (!plan.runs("inflight")) break;
    in_flight.push_back(run_in_flight(plan, n, *table));
    std::printf("   %lld in flight: %8.1f mips/s %7.3f MB/s\n", (long long)n, in_flight.back().mips_s,
                in_flight.back().mb_s);
  }

  int handled = 0;
  std::vector<Failure> failures;
  if (plan.runs("failures")) {
    const std::string down = "http://127.0.0.1:" + std::to_string(test::free_loopback_port());
    failures.push_back(run_failure(plan, "origin_down", http_storage(down), 3000ms));
    failures.push_back(run_failure(plan, "http_404", http_storage(nginx->url("missing")), 2000ms));
    failures.push_back(run_failure(plan, "http_500", http_storage(nginx->url("fail500")), 2000ms));
    test::FakeHttpOrigin truncated(test::FakeHttpOrigin::Mode::kTruncatedBody, plan.scene);
    failures.push_back(run_failure(plan, "truncated_body", http_storage(truncated.url()), 3000ms));
    test::FakeHttpOrigin shifted(test::FakeHttpOrigin::Mode::kWrongContentRange, plan.scene);
    failures.push_back(run_failure(plan, "wrong_content_range", http_storage(shifted.url()), 3000ms));
    test::FakeHttpOrigin slowloris(test::FakeHttpOrigin::Mode::kSlowloris, plan.scene);
    StorageConfig stall = http_storage(slowloris.url());
    stall.retries = 0;
    stall.low_speed_time_s = 1;
    failures.push_back(run_failure(plan, "slowloris", stall, 3500ms));
  }
  std::printf("6. origin failures:\n");
  for (const Failure& f : failures) {
    handled += f.handled;
    std::printf("   %-20s %-8s %s after %.0f ms\n", f.name, f.handled ? "handled" : "FAILED",
                to_string(static_cast<CompletionStatus>(f.status)), f.ms);
  }

  Fig12Result fig12;
  if (plan.runs("fig12")) {
    Fig12Plan fp;
    fp.quick = plan.quick;
    fp.scene = plan.scene;
    fp.work = plan.work;
    fp.out = plan.out;
    fp.config = fs::path(TEXSTREAM_STORAGE_BENCH_SOURCE_DIR) / "config" / "lavapipe.toml";
    fp.origin_url = nginx->url("unlimited");
    for (const Link& link : kLinks) fp.links.push_back({link.name, link.nominal_bytes_s});
    Stopwatch sw;
    fig12 = run_fig12(fp);
    std::printf(
        "7. Fig. 12: texstream-render (lavapipe.toml, real time, paced 30 Hz) over a %.2f s camera path at "
        "%ux%u, server reading through nginx; links capped by the slow-storage shared token bucket over "
        "nginx's unthrottled prefix (%.1f s):\n",
        fig12.path_s, fig12.width, fig12.height, sw.seconds());
    if (!fig12.failure.empty()) std::printf("   FAILED: %s\n", fig12.failure.c_str());
    for (const Fig12Row& r : fig12.rows) {
      if (!r.failure.empty()) {
        std::printf("   %-16s FAILED: %s\n", r.link.name.c_str(), r.failure.c_str());
        continue;
      }
      std::printf(
          "   %-16s ∫MSE dt %9.2f  mean PSNR %6.2f dB  %8.3f MB/s %7.1f mips/s  first mip %7.1f ms  "
          "%llu mips, %.2f MB, %llu frames\n",
          r.link.name.c_str(), r.integrated_mse, r.mean_psnr_db, r.mb_s, r.mips_s, r.first_mip_ms,
          (unsigned long long)r.mips, double(r.bytes) / 1e6, (unsigned long long)r.frames);
    }
  }
  nginx->stop();
  fs::remove_all(plan.work, ec);
  csv.close();
  timeline.close();
  const int plots = run_python(fs::path(TEXSTREAM_STORAGE_BENCH_SOURCE_DIR) / "tools" / "bench" / "storage_plots.py",
                               {plan.out.string()}, plan.out / "storage_plots.log");
  if (plots != 0) {
    std::fprintf(stderr, "storage bench: plots failed (%d), see %s\n", plots, (plan.out / "storage_plots.log").c_str());
  }
  std::printf("CSV: %s, %s, %s; plots: %s%s; %.1f s in all\n", (plan.out / "storage_bandwidth.csv").c_str(),
              (plan.out / "storage_timeline.csv").c_str(), (plan.out / "storage_fig12.csv").c_str(),
              (plan.out / "storage_fig12.png").c_str(), plots == 0 ? "" : " (FAILED)", total.seconds());

  Summary s;
  s.add("hit_p99_ratio_under_load", hit_ratio)
      .add("disk_cache_reuse", reuse.reuse)
      .add("t1_mb_s", t1_mb_s)
      .add("isdn_mb_s", isdn_mb_s)
      .add("failures_handled", fmt::format("{}/{}", handled, failures.size()));
  // Fig. 12's integrated error at the slow links over the unlimited link's (extra keys, after the issue's).
  const Fig12Row* unlimited = fig12.find("unlimited");
  for (const auto& [key, name] : {std::pair{"fig12_error_ratio_t1_vs_unlimited", "T1_1.5Mbit_s"},
                                  std::pair{"fig12_error_ratio_isdn_vs_unlimited", "ISDN_128kbit_s"}}) {
    const Fig12Row* slow = fig12.find(name);
    const bool ok =
        unlimited && slow && unlimited->failure.empty() && slow->failure.empty() && unlimited->integrated_mse > 0;
    s.add(key, ok ? slow->integrated_mse / unlimited->integrated_mse : std::numeric_limits<double>::quiet_NaN());
  }
  s.print();
  return 0;
}

}  // namespace

std::function<int()> define_storage(CLI::App& app) {
  auto plan = std::make_shared<Plan>();
  app.add_flag("--quick", plan->quick, "the short run");
  app.add_option("--out", plan->out, "folder for the CSV files and plots");
  app.add_option("--phases", plan->phases, "run only these of hits,reuse,links,policies,inflight,failures,fig12");
  return [plan] { return run_storage(*plan); };
}

TEXSTREAM_BENCH_COMMAND(storage, "remote/slow storage: nginx origin, disk cache, bimodal hits, failures",
                        define_storage);

}  // namespace texstream::bench
