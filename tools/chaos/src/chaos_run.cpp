#include "chaos_run.hpp"

#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include <thread>
#include <vector>

#include "chaos_camera_path.hpp"
#include "child_process.hpp"
#include "image_psnr.hpp"
#include "texstream/stream/stream_stats.hpp"

namespace texstream::chaos {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

namespace {

// The renderer's virtual time per frame (config key render.frame_time_ms, default 33.333 ms).
constexpr double kFrameTimeS = 0.033333;
// Frames the camera holds still at the end: a restart (50 ms), a few streaming cycles and the re-sent
// requests fit easily (measured: a 2000-texture scene converges within ~150 frames after a kill).
constexpr int kTailFrames = 450;
// Issue 9's bound on IPC time per frame.
// Issue 9: the converged frame must equal the reference to PSNR >= 45 dB.
constexpr double kPsnrBoundDb = 45.0;
// Named kill points (texture_server fault_point.hpp), armed through TEXSTREAM_FAULT_ARM's file.
constexpr const char* kFaultPoints[] = {"slot_write", "before_completion", "after_ring_push", "eviction",
                                        "mid_ring_push"};
// Share of kills sent as named points instead of a SIGKILL at a random instant.
constexpr double kNamedKillFraction = 0.5;
// How long an armed point may take to be reached: the server's watcher polls every 2 ms, and the points lie
// on the path of every served mip (eviction only once the RAM cache is full). Past this, a SIGKILL instead.
constexpr auto kNamedKillWait = std::chrono::milliseconds(1000);
// The servers' RAM cache in chaos runs (see Runner::start).
constexpr int64_t kChaosRamCacheBytes = 4 << 20;
// The server's comm name (TASK_COMM_LEN truncates "texstream-server" to 15 characters).
constexpr const char* kServerComm = "texstream-serve";

void log(const std::string& s) {
  std::printf("chaos: %s\n", s.c_str());
  std::fflush(stdout);
}

std::string fmt_num(double v, int decimals = 1) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return "inf";
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", decimals, v);
  return b;
}

// The chaos tool is a child subreaper: servers orphaned by a killed renderer become our children, so we
// can see when they exit and reap them (no zombie looks alive).
void reap_orphans() {
  int status = 0;
  while (::waitpid(-1, &status, WNOHANG) > 0) {
  }
}

bool alive(pid_t pid) {
  const auto p = read_proc(pid);
  return p && p->state != 'Z' && p->state != 'X';
}

std::optional<pid_t> server_of(pid_t renderer) {
  for (const ProcInfo& p : children_of(renderer))
    if (p.comm == kServerComm) return p.pid;
  return std::nullopt;
}

// The renderer's $TEXSTREAM_STREAM_STATS file, read by the fields that wrote it (stream_stats.hpp).
Result<stream::StreamStatsText> read_stream_stats(const fs::path& file) {
  std::ifstream in(file);
  if (!in) return make_error(ErrorCode::kNotFound, "no stream statistics file '" + file.string() + "'");
  std::ostringstream text;
  text << in.rdbuf();
  return stream::parse_stream_stats(text.str(), file.string());
}

std::string segment_needle(const std::string& segment) { return std::string("--segment\0", 10) + segment + '\0'; }

uint64_t count_shm(const std::string& prefix) {
  uint64_t n = 0;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator("/dev/shm", ec))
    if (e.path().filename().string().rfind(prefix, 0) == 0) ++n;
  return n;
}

struct Tool {
  fs::path render, server, gen;
};

struct RenderSpec {
  std::string name;  // run name: output folder, log, segment suffix
  fs::path camera_path;
  int64_t frames = 0;
  bool lockstep = false;
  std::vector<std::string> env;  // extra NAME=VALUE for the renderer (and so its servers)
};

class Runner {
 public:
  Runner(const ChaosOptions& o, const Tool& t, fs::path work, fs::path scene, std::string segment_prefix)
      : o_(o), tool_(t), work_(std::move(work)), scene_(std::move(scene)), prefix_(std::move(segment_prefix)) {}

  std::string segment(const std::string& name) const { return prefix_ + name; }
  fs::path out_dir(const std::string& name) const { return work_ / ("out-" + name); }
  fs::path log_file(const std::string& name) const { return work_ / (name + ".log"); }
  fs::path stats_file(const std::string& name) const { return work_ / (name + ".stats"); }

  Result<ChildProcess> start(const RenderSpec& r) const {
    std::vector<std::string> argv{
        tool_.render.string(), "--config", (fs::path(TEXSTREAM_SOURCE_DIR) / "config/test.toml").string(), "--set",
        "scene.dir=" + scene_.string(), "--set", "render.output_dir=" + out_dir(r.name).string(), "--set",
        "render.camera_path=" + r.camera_path.string(), "--set", "render.frames=" + std::to_string(r.frames), "--set",
        std::string("render.lockstep=") + (r.lockstep ? "true" : "false"), "--set", "render.validation=false", "--set",
        "render.write_every_frames=0", "--set", "server.executable=" + tool_.server.string(),
        // A RAM cache far smaller than the scene: the server keeps reading and
        // evicting, so the eviction kill point is on its path (the image is the same).
        "--set", "server.ram_cache_bytes=" + std::to_string(kChaosRamCacheBytes), "--set",
        "protocol.segment_name=" + segment(r.name)};
    std::vector<std::string> env = r.env;
    env.push_back("TEXSTREAM_STREAM_STATS=" + stats_file(r.name).string());
    return ChildProcess::spawn(argv, log_file(r.name), env);
  }

  fs::path final_frame(const RenderSpec& r) const {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05lld.png", static_cast<long long>(r.frames - 1));
    return out_dir(r.name) / "frames" / name;
  }

 private:
  const ChaosOptions& o_;
  Tool tool_;
  fs::path work_, scene_;
  std::string prefix_;
};

}  // namespace

bool ChaosResult::passed() const {
  return renderer_crashes == 0 && (ipc_bound_us <= 0 || ipc_p9999_us <= ipc_bound_us) && bad_payloads == 0 &&
         leaked_segments == 0 && leaked_servers == 0 && unserved_after_restart == 0 &&
         !(final_psnr_db < kPsnrBoundDb) && server_exit_after_renderer_death_ms >= 0;
}

std::string ChaosResult::summary_line() const {
  return "summary: kills=" + std::to_string(kills) + " renderer_crashes=" + std::to_string(renderer_crashes) +
         " ipc_p9999_us=" + fmt_num(ipc_p9999_us) + " bad_payloads=" + std::to_string(bad_payloads) +
         " final_psnr_db=" + fmt_num(final_psnr_db, 2) + " leaked_segments=" + std::to_string(leaked_segments) +
         " unserved_after_restart=" + std::to_string(unserved_after_restart);
}

ChaosResult run_chaos(const ChaosOptions& o) {
  ChaosResult res;
  res.ipc_bound_us = o.ipc_bound_us;
  res.final_psnr_db = std::numeric_limits<double>::quiet_NaN();
  ::prctl(PR_SET_CHILD_SUBREAPER, 1);

  Tool tool;
  fs::path bin = o.bin_dir;
  if (bin.empty()) bin = fs::read_symlink("/proc/self/exe").parent_path();
  tool.render = bin / "texstream-render";
  tool.server = bin / "texstream-server";
  tool.gen = bin / "texstream-gen";
  for (const fs::path& p : {tool.render, tool.server, tool.gen}) {
    if (::access(p.c_str(), X_OK) != 0) {
      res.notes = "missing executable " + p.string();
      ++res.renderer_crashes;
      return res;
    }
  }
  const fs::path work =
      o.work_dir.empty() ? fs::temp_directory_path() / ("texstream-chaos-" + std::to_string(::getpid())) : o.work_dir;
  fs::remove_all(work);
  fs::create_directories(work);
  const std::string prefix = "texstream-chaos-" + std::to_string(::getpid()) + "-";
  const uint64_t shm_before = count_shm(prefix);

  // ---- scene ----
  fs::path scene = o.scene;
  if (scene.empty()) {
    scene = work / "scene";
    auto gen = ChildProcess::spawn({tool.gen.string(), "--out", scene.string(), "--textures",
                                    std::to_string(o.textures), "--seed", std::to_string(o.seed), "--threads", "2"},
                                   work / "gen.log");
    if (!gen) {
      res.notes = gen.error().message;
      return res;
    }
    const auto e = gen->wait_for(10min);
    if (!e || !e->exited || e->code != 0) {
      res.notes = "texstream-gen failed (see " + (work / "gen.log").string() + ")";
      ++res.renderer_crashes;
      return res;
    }
  }
  auto scene_path = CameraPath::load(scene / "camera_path.txt");
  if (!scene_path) {
    res.notes = scene_path.error().message;
    ++res.renderer_crashes;
    return res;
  }
  log("scene " + scene.string() + ", work folder " + work.string());
  Runner runner(o, tool, work, scene, prefix);

  // ---- calibration: real-time frames per second of this machine, no kills ----
  const double kill_s = o.minutes * 60.0;
  double frame_s = 0.02;
  {
    const fs::path p = work / "calibrate_path.txt";
    std::ofstream(p) << looping_path(*scene_path, 1, 0.0).to_text();
    RenderSpec cal{"calibrate", p, 300, false, {}};
    const auto t0 = Clock::now();
    auto r = runner.start(cal);
    if (!r) {
      res.notes = r.error().message;
      ++res.renderer_crashes;
      return res;
    }
    const auto e = r->wait_for(5min);
    const double s = std::chrono::duration<double>(Clock::now() - t0).count();
    if (!e || !e->exited || e->code != 0) {
      res.notes = "calibration run failed (see " + runner.log_file("calibrate").string() + ")";
      ++res.renderer_crashes;
      return res;
    }
    frame_s = std::max(0.002, s / 300.0);  // start-up included: errs towards fewer frames
    log("calibration: " + fmt_num(frame_s * 1e3, 2) + " ms per frame (wall, start-up included)");
  }

  // ---- the kill phase: a looping fly-through, then the final pose held ----
  // 1.6x: a renderer past its start-up draws faster than the calibration run says (4.9 against 7.1 ms per
  // frame in a 30-minute run: with 1.3x it finished its frames, and ended the kill phase, at 27 minutes).
  const auto fly_frames = static_cast<int64_t>(std::ceil(kill_s * 1.6 / frame_s));
  const double fly_virtual_s = static_cast<double>(fly_frames) * kFrameTimeS;
  const int loops = static_cast<int>(std::ceil(fly_virtual_s / std::max(1.0, scene_path->duration_s()))) + 1;
  const CameraPath looped = looping_path(*scene_path, loops, 0.0);
  // Cut the loops at the last fly frame and hold that pose: the reference holds the same pose.
  std::vector<CameraKey> keys;
  for (const CameraKey& k : looped.keys())
    if (k.time_s < fly_virtual_s) keys.push_back(k);
  const CameraPose final_pose = looped.sample(fly_virtual_s);
  const double hold_s = kTailFrames * kFrameTimeS + 1.0;
  keys.push_back({fly_virtual_s, final_pose});
  keys.push_back({fly_virtual_s + hold_s, final_pose});
  const fs::path chaos_path = work / "chaos_path.txt";
  std::ofstream(chaos_path) << CameraPath(keys).to_text();
  const fs::path ref_path = work / "reference_path.txt";
  std::ofstream(ref_path) << CameraPath({{0.0, final_pose}, {hold_s, final_pose}}).to_text();

  const fs::path arm_file = work / "fault-arm";
  RenderSpec chaos{"chaos", chaos_path, fly_frames + kTailFrames, false, {"TEXSTREAM_FAULT_ARM=" + arm_file.string()}};
  log("kill phase: " + fmt_num(kill_s, 0) + " s, " + std::to_string(o.kills) + " kills planned, renderer " +
      std::to_string(chaos.frames) + " frames");
  auto render = runner.start(chaos);
  if (!render) {
    res.notes = render.error().message;
    ++res.renderer_crashes;
    return res;
  }
  std::mt19937_64 rng(o.seed * 7919 + 17);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  // Stalls are events too: pace events so that the planned kills fit the phase.
  const double events = static_cast<double>(std::max(1, o.kills)) / std::max(0.05, 1.0 - o.stall_fraction);
  const double mean_interval_s = kill_s / events;
  uint64_t named_tried = 0, named_hit = 0, named_unclaimed = 0;
  std::array<uint64_t, std::size(kFaultPoints)> point_tried{}, point_hit{};
  const auto start = Clock::now();
  // --minutes paces the kills; the phase goes on past it (restarts take time) until --kills are sent, but
  // never into the renderer's convergence tail (estimated from the calibration).
  const auto kill_end = start + std::chrono::duration_cast<Clock::duration>(
                                    std::chrono::duration<double>(0.95 * static_cast<double>(fly_frames) * frame_s));
  std::optional<ExitStatus> exit;
  uint64_t watchdog_stalls = 0;
  while (Clock::now() < kill_end && res.kills < static_cast<uint64_t>(o.kills)) {
    if ((exit = render->try_wait())) break;
    reap_orphans();
    const std::optional<pid_t> server = server_of(render->pid());
    if (!server) {
      std::this_thread::sleep_for(5ms);  // backing off or starting: nothing to kill yet
      continue;
    }
    // A random instant in this server's life: uniform in [0.05, 1.0] x the mean interval, so that with the
    // restart (back-off, start-up, attach) the kills still come about once per interval.
    // The interval is recomputed from the time and kills left, so that waits for named points and slow
    // restarts do not leave kills unsent when the phase ends.
    const double left_s =
        std::chrono::duration<double>(
            start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(kill_s)) - Clock::now())
            .count();
    const double kills_left = static_cast<double>(static_cast<uint64_t>(o.kills) - res.kills);
    const double interval_s =
        left_s > 0 ? std::min(mean_interval_s, left_s / (kills_left / std::max(0.05, 1.0 - o.stall_fraction)))
                   : 0.05 * mean_interval_s;
    const auto wait = std::chrono::duration<double>(interval_s * (0.05 + 0.95 * unit(rng)));
    const auto at = Clock::now() + std::chrono::duration_cast<Clock::duration>(wait);
    while (Clock::now() < at && !(exit = render->try_wait())) std::this_thread::sleep_for(1ms);
    if (exit) break;
    if (!alive(*server)) continue;  // the renderer replaced it already (e.g. after a stall)
    if (unit(rng) < o.stall_fraction) {
      // Storage stall / hung server: SIGSTOP for 0.1..2.5 s. Beyond protocol.heartbeat_timeout_ms (1.5 s)
      // with work outstanding the renderer's watchdog must kill it.
      const auto stall = std::chrono::duration<double>(0.1 + 2.4 * unit(rng));
      ::kill(*server, SIGSTOP);
      ++res.stalls;
      const auto until = Clock::now() + std::chrono::duration_cast<Clock::duration>(stall);
      while (Clock::now() < until && alive(*server)) std::this_thread::sleep_for(2ms);
      if (!alive(*server)) ++watchdog_stalls;
      ::kill(*server, SIGCONT);
    } else if (unit(rng) < kNamedKillFraction) {
      // A named protocol step: the server kills itself there (SIGKILL, as from outside).
      const size_t point_index = std::uniform_int_distribution<size_t>(0, std::size(kFaultPoints) - 1)(rng);
      const char* point = kFaultPoints[point_index];
      ++named_tried;
      ++point_tried[point_index];
      const fs::path tmp = arm_file.string() + ".tmp";
      std::ofstream(tmp) << point << "\n";
      fs::rename(tmp, arm_file);
      const auto until = Clock::now() + kNamedKillWait;
      while (Clock::now() < until && alive(*server)) std::this_thread::sleep_for(1ms);
      if (!alive(*server)) {
        ++named_hit;
        ++point_hit[point_index];
      } else {
        // Not reached: take the arm file back if no server claimed it (fault points not built in), and kill.
        const fs::path back = arm_file.string() + ".back";
        if (std::rename(arm_file.c_str(), back.c_str()) == 0) {
          ++named_unclaimed;
          fs::remove(back);
        }
        ::kill(*server, SIGKILL);
      }
      ++res.kills;
    } else {
      ::kill(*server, SIGKILL);
      ++res.kills;
    }
  }
  log("named kill points: " + std::to_string(named_tried) + " armed, " + std::to_string(named_hit) +
      " reached (the server died there), " + std::to_string(named_unclaimed) +
      " never claimed (a server reads the arm file only once it has passed a point: one idle since its start never "
      "does); the rest SIGKILLed");
  {
    std::string per_point = "named kill points reached / armed:";
    for (size_t i = 0; i < std::size(kFaultPoints); ++i)
      per_point += std::string(" ") + kFaultPoints[i] + " " + std::to_string(point_hit[i]) + "/" +
                   std::to_string(point_tried[i]);
    log(per_point + " (a point lies on the path of a served mip: an idle server passes none)");
  }
  log("kill phase over after " + fmt_num(std::chrono::duration<double>(Clock::now() - start).count(), 1) +
      " s: " + std::to_string(res.kills) + " SIGKILLs, " + std::to_string(res.stalls) + " stalls (" +
      std::to_string(watchdog_stalls) + " ended by the renderer's watchdog)");
  if (!exit) {
    // The rest of the fly-through and the tail, at up to 4x the calibrated frame time, plus a minute.
    const auto remaining = std::chrono::duration<double>(4.0 * frame_s * static_cast<double>(chaos.frames) + 60.0);
    exit = render->wait_for(std::chrono::duration_cast<std::chrono::milliseconds>(remaining));
  }
  reap_orphans();
  if (!exit) {
    res.notes += "renderer hung (killed); ";
    ++res.renderer_crashes;
  } else if (!exit->exited || exit->code != 0) {
    res.notes += "renderer " + exit->describe() + "; ";
    ++res.renderer_crashes;
  }
  if (auto st = read_stream_stats(runner.stats_file("chaos"))) {
    const stream::StreamStats& ss = st->stats;
    res.ipc_p9999_us = st->ipc.p9999_us;
    res.ipc_max_us = st->ipc.max_us;
    res.ipc_frames = static_cast<uint64_t>(st->ipc.frames);
    res.bad_payloads = ss.payload_checksum_failures;
    res.payloads_ok = ss.completions_ok;
    res.protocol_errors = ss.protocol_errors;
    res.unserved_after_restart = ss.unserved_after_restart;
    res.lost_resent = ss.lost_resent;
    res.server_deaths = ss.server_deaths;
    log("stream client: " + std::to_string(res.payloads_ok) + " payloads consumed, checksum verified; " +
        std::to_string(res.bad_payloads) + " checksum failures; " + std::to_string(res.protocol_errors) +
        " protocol errors; " + std::to_string(res.server_deaths) + " server deaths seen; " +
        std::to_string(res.lost_resent) + " lost requests re-sent, " + std::to_string(ss.lost_answered_in_time) +
        " answered within 2 s; IPC per frame p50 " + fmt_num(st->ipc.p50_us) + " us, p99 " + fmt_num(st->ipc.p99_us) +
        " us, p99.99 " + fmt_num(res.ipc_p9999_us) + " us, max " + fmt_num(res.ipc_max_us) + " us over " +
        std::to_string(res.ipc_frames) + " frames (" + fmt_num(st->ipc.frames_over_1ms, 0) + " over 1 ms)");
  } else {
    res.notes += st.error().message + "; ";
    ++res.renderer_crashes;
  }

  // ---- renderer death: its server must notice and exit ----
  {
    RenderSpec victim{"victim", ref_path, 100000, false, {}};
    auto r = runner.start(victim);
    std::optional<pid_t> server;
    const auto deadline = Clock::now() + 30s;
    while (r && !server && Clock::now() < deadline && !r->try_wait()) {
      server = server_of(r->pid());
      std::this_thread::sleep_for(10ms);
    }
    if (server) {
      std::this_thread::sleep_for(1s);  // let it attach and stream
      ::kill(r->pid(), SIGKILL);
      const auto t0 = Clock::now();
      while (alive(*server) && Clock::now() - t0 < 5s) {
        reap_orphans();
        std::this_thread::sleep_for(1ms);
      }
      if (!alive(*server)) {
        res.server_exit_after_renderer_death_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
      } else {
        ::kill(*server, SIGKILL);
        res.notes += "server outlived its renderer by 5 s; ";
      }
      (void)r->wait_for(5s);
      log("renderer SIGKILLed: its server exited after " + fmt_num(res.server_exit_after_renderer_death_ms, 1) + " ms");
    } else {
      res.notes += "victim renderer never spawned a server; ";
    }
    reap_orphans();
  }

  // ---- reference: no kills, lock-step, the final pose held (also removes the victim's stale segment) ----
  {
    RenderSpec ref{"reference", ref_path, kTailFrames, true, {}};
    auto r = runner.start(ref);
    const auto e = r ? r->wait_for(10min) : std::nullopt;
    if (!e || !e->exited || e->code != 0) {
      res.notes += "reference run failed (see " + runner.log_file("reference").string() + "); ";
    } else if (auto psnr = image_psnr_db(runner.final_frame(chaos), runner.final_frame(ref))) {
      res.final_psnr_db = *psnr;
    } else {
      res.notes += psnr.error().message + "; ";
    }
  }

  reap_orphans();
  res.leaked_segments = count_shm(prefix) - std::min(count_shm(prefix), shm_before);
  for (const char* name : {"chaos", "calibrate", "victim", "reference"}) {
    res.leaked_servers += processes_with_arg(segment_needle(runner.segment(name))).size();
  }
  if (res.leaked_servers) res.notes += std::to_string(res.leaked_servers) + " texstream-server process(es) left; ";
  if (!o.keep && res.passed()) fs::remove_all(work);
  return res;
}

}  // namespace texstream::chaos
