// texstream-render on a generated city (texstream-gen --textures 200) with the real server and the validation
// layer: exit code 0, zero validation errors, the PNGs it promised, textures resident. Plus the error paths of
// the command line.
#include <gtest/gtest.h>
#include <sched.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>
#include "process_test_support.hpp"
#include "texstream/common/memory_info.hpp"
#include "texstream/render/measure/frame_log.hpp"

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

const fs::path kBin = TEXSTREAM_BIN_DIR;
using texstream::test::slurp;
int run(const std::string& cmd, const fs::path& log) { return texstream::test::run_logged(cmd, log); }

fs::path fresh_dir(const std::string& name) { return texstream::test::fresh_dir("texstream_render_it_", name); }

class RenderScene : public ::testing::TestWithParam<std::string> {};

// The lock-step tests' city: texstream-gen into dir/scene.
::testing::AssertionResult generate_lockstep_city(const fs::path& dir) {
  if (run((kBin / "texstream-gen").string() + " --out " + (dir / "scene").string() +
              " --textures 300 --seed 11 --threads 2",
          dir / "gen.log") == 0) {
    return ::testing::AssertionSuccess();
  }
  return ::testing::AssertionFailure() << "texstream-gen failed:\n" << slurp(dir / "gen.log");
}

// texstream-server --segment NAME --scene SCENE as a standalone server, its stderr into `log`. Returns its pid
// (-1 if fork failed).
pid_t start_standalone_server(const std::string& name, const fs::path& scene, const fs::path& log) {
  const std::string exe = (kBin / "texstream-server").string(), scene_text = scene.string(), log_text = log.string();
  const pid_t pid = fork();
  if (pid == 0) {
    freopen(log_text.c_str(), "w", stderr);
    execl(exe.c_str(), exe.c_str(), "--segment", name.c_str(), "--scene", scene_text.c_str(), "--set",
          "server.idle_wait_ms=5", static_cast<char*>(nullptr));
    _exit(127);
  }
  return pid;
}

// One texstream-render run over the lock-step city at 320x180 into `out`, controller off; `sets` adds options.
// Its summary.json (discarded, so that the caller's checks fail, if the run failed).
nlohmann::json render_lockstep_city(const fs::path& dir, const fs::path& out, const std::string& sets) {
  const std::string cmd = (kBin / "texstream-render").string() + " --set scene.dir=" + (dir / "scene").string() +
                          " --set controller.mode=none --set render.width_px=320 --set render.height_px=180" +
                          " --set render.output_dir=" + out.string() + sets;
  EXPECT_EQ(run(cmd, dir / "render.log"), 0) << slurp(dir / "render.log");
  return nlohmann::json::parse(slurp(out / "summary.json"), nullptr, false);
}

// Every PNG in a/frames must exist in b/frames with the same bytes; returns how many were compared.
int expect_same_frames(const fs::path& a, const fs::path& b, const std::string& what) {
  int compared = 0;
  for (const auto& entry : fs::directory_iterator(a / "frames")) {
    const fs::path other = b / "frames" / entry.path().filename();
    EXPECT_TRUE(fs::exists(other)) << other;
    EXPECT_TRUE(slurp(entry.path()) == slurp(other)) << entry.path().filename() << " differs " << what;
    ++compared;
  }
  return compared;
}

}  // namespace

TEST_P(RenderScene, TinyCityRendersWithoutValidationErrors) {
  const std::string format = GetParam();
  const fs::path dir = fresh_dir("scene_" + format);
  ASSERT_EQ(run((kBin / "texstream-gen").string() + " --out " + (dir / "scene").string() +
                    " --textures 200 --seed 7 --threads 1 --format " + format,
                dir / "gen.log"),
            0)
      << slurp(dir / "gen.log");
  const fs::path out = dir / "out";
  const std::string cmd = (kBin / "texstream-render").string() + " --set scene.dir=" + (dir / "scene").string() +
                          " --set render.validation=true --set render.lockstep=true --set controller.mode=none" +
                          " --set render.frames=30 --set render.write_every_frames=10" +
                          " --set cache.format=" + format + " --set render.output_dir=" + out.string();
  const int rc = run(cmd, dir / "render.log");
  const std::string log = slurp(dir / "render.log");
  ASSERT_EQ(rc, 0) << log;
  for (const char* f : {"frame_00000.png", "frame_00010.png", "frame_00020.png", "frame_00029.png"}) {
    EXPECT_TRUE(fs::exists(out / "frames" / f)) << f << "\n" << log;
  }
  ASSERT_TRUE(fs::exists(out / "summary.json")) << log;
  const auto summary = nlohmann::json::parse(slurp(out / "summary.json"));
  EXPECT_EQ(summary["frames"].get<int>(), 30);
  EXPECT_EQ(summary["validation_errors"].get<int>(), 0) << log;
  EXPECT_GT(summary["textures_resident"].get<int>(), 0) << log;
  EXPECT_GT(summary["mips_streamed"].get<int>(), 0);
  EXPECT_EQ(summary["protocol_errors"].get<int>(), 0);
  EXPECT_NE(summary["device"].get<std::string>().find("llvmpipe"), std::string::npos);
  EXPECT_NE(log.find("output folder"), std::string::npos);
  fs::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Formats, RenderScene, ::testing::Values("rgba8", "bc1"));

TEST(RenderCli, UnknownKeyIsExitTwoAndNamed) {
  const fs::path dir = fresh_dir("cli");
  const int rc = run((kBin / "texstream-render").string() + " --set render.no_such_key=1", dir / "log");
  EXPECT_EQ(rc, 2);
  EXPECT_NE(slurp(dir / "log").find("no_such_key"), std::string::npos) << slurp(dir / "log");
  EXPECT_EQ(run((kBin / "texstream-render").string() + " --bogus-flag", dir / "log2"), 2);
  fs::remove_all(dir);
}

TEST(RenderCli, MissingSceneNamesThePath) {
  const fs::path dir = fresh_dir("noscene");
  const int rc = run((kBin / "texstream-render").string() + " --set scene.dir=" + (dir / "nowhere").string() +
                         " --set render.output_dir=" + (dir / "out").string(),
                     dir / "log");
  EXPECT_EQ(rc, 1);
  EXPECT_NE(slurp(dir / "log").find("nowhere"), std::string::npos) << slurp(dir / "log");
  fs::remove_all(dir);
}

// A server that cannot start (here a script that exits with status 2 at once, as texstream-server does on a
// bad option) ends a render.preload_all run within a second or so, naming how it ended and the key to check
// (before, each preload round waited out the restart back-off, up to the colormap-only retry of 30 s, for up
// to 64 rounds), a lock-step run at its first death (before, it drew colormap frames and reported success),
// and a streaming run at its third refusal or at its end. `timeout` keeps a regression from hanging the suite.
TEST(RenderCli, AServerThatCannotStartEndsPreloadLockstepAndStreamingRunsWithItsReason) {
  const fs::path dir = fresh_dir("badserver");
  ASSERT_TRUE(generate_lockstep_city(dir));
  const fs::path fake = dir / "refusing-server.sh";
  { std::ofstream(fake) << "#!/bin/sh\necho 'refusing-server: unknown option' >&2\nexit 2\n"; }
  fs::permissions(fake, fs::perms::owner_all);
  struct Case {
    std::string sets;
    std::vector<std::string> messages;
    double within_s;
  };
  const std::vector<Case> runs = {
      {"render.preload_all=true", {"died before attaching to the segment 3 times in a row", "server.executable"}, 60},
      {"render.lockstep=true", {"render.lockstep: texstream-server died during the run"}, 60},
      // Streaming runs: a server that exits with status 2 (bad arguments, configuration or scene) refuses for
      // good; before, the run drew colormap frames, restarting it, and reported success. A long run (20000
      // paced frames: 333 s, past the `timeout 120`) ends at the third refusal (back-off 50 + 100 ms), not at its
      // end; a run shorter than that ends with the refusals it saw (1 on a quiet machine; a slower one may see
      // a second before its 5 frames are drawn).
      {"render.lockstep=false --set render.frames=20000",
       {"texstream-server refused to start, 3 times in a row", "[server] and [storage] keys"},
       60},
      {"render.lockstep=false", {"texstream-server refused to start, ", "in a row"}, 60}};
  for (const auto& [mode, messages, within_s] : runs) {
    const auto t0 = std::chrono::steady_clock::now();
    const int rc =
        run("timeout 120 " + (kBin / "texstream-render").string() + " --set scene.dir=" + (dir / "scene").string() +
                " --set render.frames=5 --set render.width_px=160" +
                " --set render.height_px=90 --set render.output_dir=" + (dir / "out").string() +
                " --set server.executable=" + fake.string() + " --set " + mode,
            dir / "render.log");
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const std::string log = slurp(dir / "render.log");
    EXPECT_EQ(rc, 1) << mode << "\n" << log;
    EXPECT_LT(seconds, within_s) << mode;
    for (const std::string& message : messages) {
      EXPECT_NE(log.find(message), std::string::npos) << mode << "\n" << log;
    }
    EXPECT_NE(log.find("exited with status 2"), std::string::npos) << mode << "\n" << log;
  }
  fs::remove_all(dir);
}

// Frames written to a full disk (a 64 KiB tmpfs in a mount namespace of its own; root only): the run ends
// with an error naming the frame and the cause, and every PNG left under a frame's name is whole. Before,
// stbi_write_png() ignored fwrite's result: empty and truncated PNGs, and the run went on (it failed only at
// cache.json).
TEST(RenderCli, AFullOutputDiskEndsTheRunAndLeavesNoTruncatedFrame) {
  const fs::path dir = fresh_dir("fulldisk");
  ASSERT_TRUE(generate_lockstep_city(dir));
  const fs::path mnt = dir / "mnt";
  fs::create_directories(mnt);
  const std::string render = (kBin / "texstream-render").string() + " --set scene.dir=" + (dir / "scene").string() +
                             " --set render.frames=40 --set render.write_every_frames=1 --set render.width_px=160" +
                             " --set render.height_px=90 --set render.output_dir=" + (mnt / "out").string();
  // Run inside the namespace by a script, which also checks the PNGs there (the mount is gone outside it):
  // a PNG is whole if it ends with the IEND chunk's CRC (ae 42 60 82).
  const fs::path script = dir / "fulldisk.sh";
  std::ofstream(script)
      << "#!/bin/sh\n"
      << "mount -t tmpfs -o size=64k tmpfs '" << mnt.string() << "' || exit 77\n"
      << "timeout 120 " << render << "\n"
      << "echo render_rc=$?\n"
      << "n=0\n"
      << "for f in '" << (mnt / "out" / "frames").string() << "'/*.png; do\n"
      << "  [ -e \"$f\" ] || continue\n"
      << "  tail -c 4 \"$f\" | od -An -tx1 | tr -d ' \\n' | grep -q '^ae426082$' || echo \"TRUNCATED $f\"\n"
      << "  n=$((n+1))\n"
      << "done\n"
      << "echo whole $n\n";
  fs::permissions(script, fs::perms::owner_all);
  const int rc = run("unshare -m " + script.string(), dir / "render.log");
  const std::string log = slurp(dir / "render.log");
  if (rc == 77 || log.find("render_rc=") == std::string::npos) GTEST_SKIP() << "no mount namespace here:\n" << log;
  EXPECT_NE(log.find("render_rc=1"), std::string::npos) << log;
  EXPECT_NE(log.find("cannot write the frame (No space left on device)"), std::string::npos) << log;
  EXPECT_EQ(log.find("TRUNCATED"), std::string::npos) << log;
  EXPECT_NE(log.find("whole "), std::string::npos) << log;
  fs::remove_all(dir);
}

// A standalone texstream-server (--segment NAME, started first: it waits for the renderer) serves renderers
// configured with protocol.segment_name = NAME:
// - with server.spawn = false, the renderer starts no server of its own;
// - with the default (spawn), the renderer's child finds the segment held and leaves; the renderer uses the
//   standalone one (before, both attached to the one segment: slots released twice, protocol errors).
// Each run (render.preload_all: it waits for every mip) must stream with no protocol error.
TEST(RenderCli, AStandaloneServerServesRenderersOnItsSegmentName) {
  const fs::path dir = fresh_dir("standalone");
  ASSERT_TRUE(generate_lockstep_city(dir));
  const std::string name = "ts-test-standalone-" + std::to_string(getpid());
  const pid_t server = start_standalone_server(name, dir / "scene", dir / "server.log");
  ASSERT_GT(server, 0);
  for (const std::string spawn : {"false", "true"}) {
    const fs::path out = dir / ("out-" + spawn);
    // With a child, the run lasts at least 1.5 s of paced frames: the standalone server looks for a new
    // renderer every 100 ms, and a 0.2 s run could end before it ever tried the segment (CI, once).
    const std::string frames = spawn == "true" ? "45 --set render.pace_frames=true" : "5";
    const int rc =
        run("timeout 120 " + (kBin / "texstream-render").string() + " --set scene.dir=" + (dir / "scene").string() +
                " --set render.frames=" + frames + " --set render.width_px=160" +
                " --set render.height_px=90 --set render.output_dir=" + out.string() +
                " --set render.preload_all=true --set protocol.segment_name=" + name + " --set server.spawn=" + spawn,
            dir / ("render-" + spawn + ".log"));
    const std::string log = slurp(dir / ("render-" + spawn + ".log"));
    EXPECT_EQ(rc, 0) << "server.spawn=" << spawn << "\n" << log;
    const nlohmann::json summary = nlohmann::json::parse(slurp(out / "summary.json"), nullptr, false);
    ASSERT_FALSE(summary.is_discarded()) << log;
    EXPECT_GT(summary["mips_streamed"].get<int>(), 0) << log;
    EXPECT_EQ(summary["protocol_errors"].get<int>(), 0) << log;
    if (spawn == "false") {
      EXPECT_EQ(log.find("texstream-server started"), std::string::npos) << "a child was spawned:\n" << log;
    } else {
      // One of the two took the segment; the other stood aside, whichever came first: the child says so (and
      // the renderer, if it reaps the child before the run ends), or the standalone one waits.
      const bool child_left = log.find("is already served by texstream-server") != std::string::npos ||
                              log.find("is served by a standalone texstream-server") != std::string::npos;
      const bool standalone_waited = slurp(dir / "server.log").find("waiting until it is free") != std::string::npos;
      EXPECT_TRUE(child_left || standalone_waited) << log << "\n" << slurp(dir / "server.log");
    }
  }
  // server.batch_scheduling (default true): every thread of the server runs SCHED_BATCH, so that its wake-ups
  // never preempt a renderer's frame thread (docs/design/syscalls.md).
  int threads = 0;
  for (const auto& task : fs::directory_iterator("/proc/" + std::to_string(server) + "/task")) {
    const pid_t tid = std::stoi(task.path().filename().string());
    const int policy = sched_getscheduler(tid);
    if (policy < 0) continue;  // a thread that ended meanwhile
    EXPECT_EQ(policy, SCHED_BATCH) << "server thread " << tid;
    ++threads;
  }
  EXPECT_GE(threads, 1);
  kill(server, SIGTERM);
  int status = 0;
  waitpid(server, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << slurp(dir / "server.log");
  fs::remove_all(dir);
}

// A standalone texstream-server started on another scene than the renderer's (server.spawn = false): it
// refuses the segment (the texture tables differ), and the renderer's run ends at once with an error naming
// that server, while the server waits for the next renderer. Before, the server exited and the renderer's
// preload (render.preload_all) waited for ever for a server, with one warning after 3 s.
TEST(RenderCli, AStandaloneServerOfAnotherSceneEndsTheRunNamingIt) {
  const fs::path dir = fresh_dir("otherscene");
  ASSERT_TRUE(generate_lockstep_city(dir));
  ASSERT_EQ(run((kBin / "texstream-gen").string() + " --out " + (dir / "other").string() +
                    " --textures 20 --seed 3 --threads 2",
                dir / "gen-other.log"),
            0)
      << slurp(dir / "gen-other.log");
  const std::string name = "ts-test-otherscene-" + std::to_string(getpid());
  const pid_t server = start_standalone_server(name, dir / "other", dir / "server.log");
  ASSERT_GT(server, 0);
  const auto t0 = std::chrono::steady_clock::now();
  const int rc =
      run("timeout 120 " + (kBin / "texstream-render").string() + " --set scene.dir=" + (dir / "scene").string() +
              " --set render.frames=5 --set render.width_px=160" +
              " --set render.height_px=90 --set render.output_dir=" + (dir / "out").string() +
              " --set render.preload_all=true --set protocol.segment_name=" + name + " --set server.spawn=false",
          dir / "render.log");
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const std::string log = slurp(dir / "render.log");
  EXPECT_EQ(rc, 1) << log;
  EXPECT_LT(seconds, 60.0) << log;
  EXPECT_NE(log.find("standalone texstream-server pid " + std::to_string(server) + " refused segment '" + name +
                     "': it reads another scene"),
            std::string::npos)
      << log;
  const std::string server_log = slurp(dir / "server.log");
  EXPECT_NE(server_log.find("refused, waiting for the next renderer"), std::string::npos) << server_log;
  int status = 0;
  EXPECT_EQ(waitpid(server, &status, WNOHANG), 0) << "the standalone server exited:\n" << server_log;
  kill(server, SIGTERM);
  waitpid(server, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << slurp(dir / "server.log");
  fs::remove_all(dir);
}

// A RAM cache budget no machine here can hold (1 TiB, the key's maximum): the renderer refuses before it
// spawns a server, and a server started by hand refuses too, both naming the key and the limit. Before, the
// server pre-faulted its cache until the kernel OOM-killed it, and the renderer restarted it for ever.
TEST(RenderCli, ARamCacheLargerThanTheMachineIsRefusedNamingTheKey) {
  if (texstream::read_memory_info().limit > (1ull << 40) + (1ull << 30)) GTEST_SKIP() << "more than 1 TiB of memory";
  const fs::path dir = fresh_dir("hugecache");
  ASSERT_TRUE(generate_lockstep_city(dir));
  const std::string huge = " --set server.ram_cache_bytes=1099511627776";
  const auto t0 = std::chrono::steady_clock::now();
  const int rc =
      run("timeout 120 " + (kBin / "texstream-render").string() + " --set scene.dir=" + (dir / "scene").string() +
              " --set render.frames=5 --set render.width_px=160" +
              " --set render.height_px=90 --set render.output_dir=" + (dir / "out").string() + huge,
          dir / "render.log");
  const std::string log = slurp(dir / "render.log");
  EXPECT_NE(rc, 0) << log;
  EXPECT_NE(rc, 124) << "timed out:\n" << log;
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 60.0);
  EXPECT_NE(log.find("config: key 'server.ram_cache_bytes': the server needs"), std::string::npos) << log;
  EXPECT_NE(log.find("but this machine allows"), std::string::npos) << log;
  EXPECT_EQ(log.find("[server]"), std::string::npos) << "a server was spawned:\n" << log;

  const int server_rc = run("timeout 60 " + (kBin / "texstream-server").string() + " --segment texstream-none-" +
                                std::to_string(getpid()) + " --scene " + (dir / "scene").string() + huge,
                            dir / "server.log");
  const std::string server_log = slurp(dir / "server.log");
  EXPECT_EQ(server_rc, 2) << server_log;
  EXPECT_NE(server_log.find("config: key 'server.ram_cache_bytes'"), std::string::npos) << server_log;
  fs::remove_all(dir);
}

// Lock-step (render.lockstep): two runs of the same path and scene give byte-identical frames and the same
// streaming counts, whatever the server's worker threads and the machine load did (DESIGN "Determinism").
// TEXSTREAM_TEST_REALTIME=1 runs the same check in real-time mode, where it fails (frames outrun the server).
// The other source of run-to-run difference, cache placement in completion order (fixed by OrderedCommitSink),
// shows only on larger runs (4000 textures, 960x540: ~30 pixels 1 LSB apart) and is not exercised at this size.
TEST(RenderLockstep, TwoRunsGiveIdenticalFrames) {
  const std::string lockstep = std::getenv("TEXSTREAM_TEST_REALTIME") ? "false" : "true";  // to show it can fail
  const fs::path dir = fresh_dir("lockstep");
  ASSERT_TRUE(generate_lockstep_city(dir));
  std::vector<nlohmann::json> summaries;
  for (int i = 0; i < 2; ++i) {
    summaries.push_back(render_lockstep_city(
        dir, dir / ("out" + std::to_string(i)),
        " --set render.lockstep=" + lockstep + " --set render.frames=24 --set render.write_every_frames=4"));
  }
  EXPECT_GT(summaries[0]["mips_streamed"].get<int>(), 0);
  EXPECT_EQ(summaries[0]["mips_streamed"], summaries[1]["mips_streamed"]);
  EXPECT_EQ(summaries[0]["textures_resident"], summaries[1]["textures_resident"]);
  // frames 0, 4, ..., 20 and the last (23)
  EXPECT_EQ(expect_same_frames(dir / "out0", dir / "out1", "between two lock-step runs"), 7);
  fs::remove_all(dir);
}

// render.feedback_pairs (texstream-bench visibility's cost measurement): each frame is drawn a second time
// without feedback. The second drawing must change nothing the run shows or streams (lock-step: the same frames
// byte for byte and the same mips as a run without pairs), and frames.csv carries both latencies.
TEST(RenderLockstep, FeedbackPairsDrawTheSameFramesAndLogBothLatencies) {
  const fs::path dir = fresh_dir("pairs");
  ASSERT_TRUE(generate_lockstep_city(dir));
  std::vector<nlohmann::json> summaries;
  for (const char* pairs : {"false", "true"}) {
    summaries.push_back(render_lockstep_city(dir, dir / (std::string("pairs_") + pairs),
                                             std::string(" --set render.lockstep=true --set render.frames=16") +
                                                 " --set render.validation=true --set render.feedback_pairs=" + pairs +
                                                 " --set render.write_every_frames=5"));
  }
  EXPECT_GT(summaries[0]["mips_streamed"].get<int>(), 0);
  EXPECT_EQ(summaries[0]["mips_streamed"], summaries[1]["mips_streamed"]);
  EXPECT_EQ(summaries[0]["streaming_cycles"], summaries[1]["streaming_cycles"]);
  EXPECT_EQ(summaries[1]["validation_errors"].get<int>(), 0);
  // frames 0, 5, 10 and the last (15)
  EXPECT_EQ(expect_same_frames(dir / "pairs_false", dir / "pairs_true", "with render.feedback_pairs"), 4);
  const auto paired = texstream::render::read_frame_log(dir / "pairs_true" / "frames.csv");
  ASSERT_TRUE(paired.ok()) << paired.error().message;
  ASSERT_EQ(paired->size(), 16u);
  for (const auto& f : *paired) {
    EXPECT_GT(f.latency_off_ms, 0.0) << "frame " << f.index << ": latency_off_ms";  // NaN fails too
    EXPECT_GT(f.latency_ms, 0.0) << "frame " << f.index;
  }
  const auto plain = texstream::render::read_frame_log(dir / "pairs_false" / "frames.csv");
  ASSERT_TRUE(plain.ok()) << plain.error().message;
  for (const auto& f : *plain) {
    EXPECT_TRUE(std::isnan(f.latency_off_ms)) << "frame " << f.index << ": latency_off_ms without pairs";
  }
  // Where the latency goes (frames.csv's parts): each part >= 0, every frame submits, and the parts are pieces
  // of the latency, the twin's drawing in neither.
  for (const auto* log : {&*plain, &*paired}) {
    for (const auto& f : *log) {
      const double parts[] = {f.plan_ms, f.intake_ms, f.bind_ms, f.record_ms, f.gpu_ms, f.cycle_ms};
      double sum = 0;
      for (double p : parts) {
        EXPECT_GE(p, 0.0) << "frame " << f.index;
        sum += p;
      }
      EXPECT_GT(f.gpu_ms, 0.0) << "frame " << f.index;
      EXPECT_LE(sum, f.latency_ms + 1e-3) << "frame " << f.index;
      EXPECT_TRUE(std::isnan(f.pace_mips)) << "frame " << f.index << ": a pace in mode none";
    }
  }
  // Not with a window: refused at start, naming the key.
  const int rc = run((kBin / "texstream-render").string() + " --set scene.dir=" + (dir / "scene").string() +
                         " --set render.window=true --set render.feedback_pairs=true --set render.output_dir=" +
                         (dir / "win").string(),
                     dir / "win.log");
  EXPECT_NE(rc, 0);
  EXPECT_NE(slurp(dir / "win.log").find("render.feedback_pairs"), std::string::npos) << slurp(dir / "win.log");
  fs::remove_all(dir);
}
