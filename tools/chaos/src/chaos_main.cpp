// texstream-chaos [--quick] [--kills N] [--minutes M] [--scene DIR] [--textures N] [--seed S] [--keep]
// Kills and stalls texstream-server under a rendering texstream-render and checks issue 9's invariants.
// The last line is `summary: kills=… renderer_crashes=… ipc_p9999_us=… bad_payloads=… final_psnr_db=…
// leaked_segments=… unserved_after_restart=…`. Exit 0 when every invariant holds, 1 otherwise.
#include <CLI/CLI.hpp>

#include <cstdio>

#include "chaos_run.hpp"

int main(int argc, char** argv) {
  CLI::App app{"texstream-chaos: SIGKILL / SIGSTOP texstream-server under a rendering texstream-render"};
  texstream::chaos::ChaosOptions o;
  bool quick = false;
  int kills = -1;
  double minutes = -1;
  std::string scene, bin_dir, work_dir;
  app.add_flag("--quick", quick, "CI size: 20 kills paced over about 60 s, a 1500-texture scene");
  app.add_option("--kills", kills, "SIGKILLs to send (default 1000, quick 20)")->check(CLI::Range(1, 1000000));
  app.add_option("--minutes", minutes, "length of the kill phase (default 30, quick 1)")
      ->check(CLI::Range(0.05, 1440.0));
  app.add_option("--scene", scene, "scene folder (default: texstream-gen into the work folder)");
  app.add_option("--textures", o.textures, "textures of the generated scene")->check(CLI::Range(50u, 1000000u));
  app.add_option("--seed", o.seed, "seed of the scene and of the kill schedule");
  app.add_option("--bin-dir", bin_dir, "folder of texstream-render/-server/-gen (default: next to this program)");
  app.add_option("--work-dir", work_dir, "work folder (default: a temp folder, removed after a clean run)");
  app.add_flag("--keep", o.keep, "keep the work folder (logs, frames, statistics)");
  app.add_option("--stall-fraction", o.stall_fraction, "share of events that are SIGSTOP stalls")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--ipc-bound-us", o.ipc_bound_us,
                 "p99.99 bound on a frame's IPC time, an invariant (default 1000); 0: report only")
      ->check(CLI::Range(0.0, 1e9));
  CLI11_PARSE(app, argc, argv);
  o.quick = quick;
  if (quick) o.textures = std::min<uint32_t>(o.textures, 1500);
  o.kills = kills > 0 ? kills : (quick ? 20 : 1000);
  o.minutes = minutes > 0 ? minutes : (quick ? 1.0 : 30.0);
  o.scene = scene;
  o.bin_dir = bin_dir;
  o.work_dir = work_dir;

  const texstream::chaos::ChaosResult r = texstream::chaos::run_chaos(o);
  if (!r.notes.empty()) std::printf("chaos: problems: %s\n", r.notes.c_str());
  std::printf(
      "chaos: %llu payloads verified, %llu stalls, %llu server deaths seen by the renderer, server exit after "
      "renderer death %.1f ms, %s\n",
      static_cast<unsigned long long>(r.payloads_ok), static_cast<unsigned long long>(r.stalls),
      static_cast<unsigned long long>(r.server_deaths), r.server_exit_after_renderer_death_ms,
      r.passed() ? "all invariants hold" : "INVARIANTS VIOLATED");
  std::printf("%s\n", r.summary_line().c_str());
  return r.passed() ? 0 : 1;
}
