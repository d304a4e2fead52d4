#pragma once
// One chaos run (issue 9): a generated scene, a calibration run, the renderer flying a looping path while
// its texstream-server is SIGKILLed at random instants and stalled with SIGSTOP/SIGCONT, a renderer-death
// check (the server must exit), a reference run without kills, and the invariants of the summary line.
#include <cstdint>
#include <filesystem>
#include <string>

namespace texstream::chaos {

struct ChaosOptions {
  bool quick = false;
  int kills = 1000;             // SIGKILLs to send during the kill phase
  double minutes = 30.0;        // length of the kill phase
  std::filesystem::path scene;  // empty: texstream-gen into the work folder
  uint32_t textures = 2000;     // generated scene size
  uint64_t seed = 1;
  std::filesystem::path bin_dir;   // texstream-render, -server, -gen; empty: next to this program
  std::filesystem::path work_dir;  // empty: a temp folder, removed unless keep
  bool keep = false;
  double stall_fraction = 0.15;  // share of events that are SIGSTOP stalls instead of kills
  // Issue 9's bound on the p99.99 of a frame's IPC time; 0: reported, not an invariant (CI on a shared
  // 2-core machine, where scheduling noise alone exceeds 1 ms; the long run keeps the bound).
  double ipc_bound_us = 1000.0;
};

struct ChaosResult {
  uint64_t kills = 0;
  uint64_t stalls = 0;
  uint64_t renderer_crashes = 0;  // the renderer ended by a signal or a failure exit, or hung
  double ipc_p9999_us = 0;
  double ipc_bound_us = 1000.0;  // from ChaosOptions; 0: not checked by passed()
  double ipc_max_us = 0;
  uint64_t ipc_frames = 0;
  uint64_t bad_payloads = 0;  // payloads whose checksum failed (never committed, but a bug with a real server)
  uint64_t payloads_ok = 0;   // payloads consumed, checksum verified
  uint64_t protocol_errors = 0;
  double final_psnr_db = 0;  // NaN when not measured
  uint64_t leaked_segments = 0;
  uint64_t leaked_servers = 0;
  uint64_t unserved_after_restart = 0;
  uint64_t lost_resent = 0;
  uint64_t server_deaths = 0;
  double server_exit_after_renderer_death_ms = -1;  // -1: the server did not exit within 5 s
  std::string notes;                                // what went wrong, for the log

  bool passed() const;
  std::string summary_line() const;
};

ChaosResult run_chaos(const ChaosOptions& options);

}  // namespace texstream::chaos
