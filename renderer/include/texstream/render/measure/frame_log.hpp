#pragma once
// Per-frame measurements of one texstream-render run (issue 8), written as <output_dir>/frames.csv next to
// summary.json and read back by texstream-bench path. One row per frame; the column names are the contract
// between the two (frame_log_columns()), so both sides use this one file.
//
// Quantities that a frame does not have are NaN in memory and an empty field in the file: image error
// without render.reference_dir, pop-in while the camera moves, the mip deficit before the first visibility
// list.
//
// Columns, in file order (frame_log_columns(); a unit test keeps this list equal to it), each the field of
// FrameRecord that says what it holds:
//   frame, time_s, wall_s, latency_ms, waited_ms, tw_ms, load_size_mb, mip_bias, mips, bytes, bound_pages,
//   server_hit_rate, in_flight, camera_still, mse, psnr_db, ssim, popin_mse, latency_off_ms, list_fresh,
//   mip_deficit, wasted_bytes, plan_ms, intake_ms, bind_ms, record_ms, gpu_ms, cycle_ms, pace_mips
//
// The stream-quality columns (docs/design/stream_metrics.md):
//   mip_deficit   Σ W·max(0, displayed − wanted) / Σ W over the textures of the latest visibility list read
//                 back (this frame's when list_fresh, else the last one read; W = the list's weight, wanted =
//                 its desired level without the mip bias), displayed = max(wanted, finest resident level), or
//                 the texture's level count when nothing is resident. Residency is taken at the END of the
//                 frame, after its uploads were published: the state the NEXT frame draws with.
//   wasted_bytes  running total of the bytes of streamed mips that have left the cache (evicted or replaced)
//                 without ever having been displayed while resident; mips still resident at the end of the
//                 run are added in summary.json only (wasted_bytes, wasted_bytes_frac).
//
// Where a frame's latency goes (wall clock, so lock-step runs are not compared on them; they add up to
// latency_ms less the small steps between them):
//   plan_ms    broad phase, draw lists, new meshes (frame_plan)
//   intake_ms  completions taken into the staging ring (lock-step waits excluded)
//   bind_ms    the cache's page binds for the frame's copies (prepare_uploads: one vkQueueBindSparse)
//   record_ms  the rest of the command buffer's recording
//   gpu_ms     submission to fence: the binds' wait, the copies, the passes
//   cycle_ms   the visibility list read back and the streaming cycle started from it
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "texstream/common/result.hpp"

namespace texstream::render {

struct FrameRecord {
  uint64_t index = 0;
  double time_s = 0;           // virtual time along the camera path: index * render.frame_time_ms
  double wall_s = 0;           // wall time from the start of frame 0 to the end of this frame
  double latency_ms = 0;       // frame latency (lock-step waits for the server excluded; blocking loads included)
  double waited_ms = 0;        // lock-step: time spent waiting for the previous cycle's answers
  double tw_ms = 0;            // t_w, weighted maximum frame latency (seed 000 Eq. 5)
  double load_size_mb = 0;     // s for the next cycle, 10^6 bytes
  double mip_bias = 0;         // b for the next cycle, levels
  uint64_t mips = 0;           // mips uploaded and published during this frame
  uint64_t bytes = 0;          // their bytes
  uint64_t bound_pages = 0;    // sparse pages bound in the cache at the end of the frame
  double server_hit_rate = 0;  // server RAM cache hits / lookups during this frame (NaN: no lookups)
  uint64_t in_flight = 0;      // requests outstanding at the server after the frame
  bool camera_still = false;   // the pose equals the previous frame's (a pause): pop-in is measured
  double mse = 0;              // against the reference frame (NaN: no reference)
  double psnr_db = 0;
  double ssim = 0;
  double popin_mse = 0;       // MSE to the previous frame while the camera is still (NaN otherwise)
  double latency_off_ms = 0;  // render.feedback_pairs: the same frame drawn without feedback (NaN otherwise)
  bool list_fresh = false;    // the frame read the visibility list back (a streaming cycle started from it)
  double mip_deficit = 0;     // weighted mip deficit, levels (above; NaN before the first list)
  uint64_t wasted_bytes = 0;  // bytes of mips that left the cache never displayed, all frames so far (above)
  double plan_ms = 0;         // the latency's parts (above)
  double intake_ms = 0;
  double bind_ms = 0;
  double record_ms = 0;
  double gpu_ms = 0;
  double cycle_ms = 0;
  double pace_mips = 0;  // mode auto: the most mips the next frame takes in (NaN: no pace)
};

// Column names, in file order.
const std::vector<std::string>& frame_log_columns();

std::string frame_log_csv(const std::vector<FrameRecord>& frames);
Status write_frame_log(const std::filesystem::path& file, const std::vector<FrameRecord>& frames);
// Fails naming the file and line for a header that differs from frame_log_columns() or a bad field.
Result<std::vector<FrameRecord>> read_frame_log(const std::filesystem::path& file);
Result<std::vector<FrameRecord>> parse_frame_log(const std::string& text, const std::string& what);

}  // namespace texstream::render
