// texstream-bench path analysis: frames.csv round trip, seed-table statistics, windowed rates, recovery after
// a cut on synthetic PSNR series, cuts and sections of a camera path, the lock-step comparison, p99 latency,
// integrated mip deficit, time to detail after a cut and the headline ratios.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

#include "path_analysis.hpp"
#include "texstream/render/measure/frame_log.hpp"

namespace texstream::bench {
namespace {

using render::FrameRecord;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::vector<FrameRecord> series(size_t n, double dt) {
  std::vector<FrameRecord> v(n);
  for (size_t i = 0; i < n; ++i) {
    v[i].index = i;
    v[i].time_s = static_cast<double>(i) * dt;
    v[i].wall_s = static_cast<double>(i + 1) * dt;
    v[i].mse = v[i].psnr_db = v[i].ssim = v[i].popin_mse = v[i].mip_deficit = kNaN;
  }
  return v;
}

constexpr double kInf = std::numeric_limits<double>::infinity();

TEST(FrameLog, RoundTripKeepsValuesAndNaN) {
  auto v = series(3, 1.0 / 30);
  v[1].latency_ms = 12.345678901234567;
  v[1].mips = 17;
  v[1].bytes = 123456789012ull;
  v[1].camera_still = true;
  v[2].mse = 0.1;
  v[2].psnr_db = 58.1;
  v[2].ssim = 0.99;
  v[2].server_hit_rate = kNaN;
  v[1].list_fresh = true;
  v[1].mip_deficit = 1.25;
  v[2].mip_deficit = 0.0;
  v[2].wasted_bytes = 4096;
  auto back = render::parse_frame_log(render::frame_log_csv(v), "mem");
  ASSERT_TRUE(back.ok()) << back.error().message;
  ASSERT_EQ(back->size(), 3u);
  EXPECT_EQ((*back)[1].latency_ms, v[1].latency_ms);  // %.17g: the same double
  EXPECT_EQ((*back)[1].bytes, v[1].bytes);
  EXPECT_TRUE((*back)[1].camera_still);
  EXPECT_FALSE((*back)[0].camera_still);
  EXPECT_TRUE(std::isnan((*back)[0].mse));
  EXPECT_TRUE(std::isnan((*back)[2].server_hit_rate));
  EXPECT_EQ((*back)[2].ssim, 0.99);
  EXPECT_TRUE((*back)[1].list_fresh);
  EXPECT_FALSE((*back)[2].list_fresh);
  EXPECT_TRUE(std::isnan((*back)[0].mip_deficit));  // before the first list
  EXPECT_EQ((*back)[1].mip_deficit, 1.25);
  EXPECT_EQ((*back)[2].mip_deficit, 0.0);
  EXPECT_EQ((*back)[2].wasted_bytes, 4096u);
  EXPECT_EQ(lockstep_difference(v, *back), "");
}

TEST(FrameLog, TheHeaderCommentListsTheColumnsInFileOrder) {
  std::ifstream in(TEXSTREAM_SOURCE_DIR "/renderer/include/texstream/render/measure/frame_log.hpp");
  ASSERT_TRUE(in) << "frame_log.hpp not found";
  // The comment block after "Columns, in file order": its indented lines hold the names, comma-separated.
  std::string line, listed;
  bool in_list = false;
  while (std::getline(in, line)) {
    if (line.find("Columns, in file order") != std::string::npos) {
      in_list = true;
    } else if (in_list && line.rfind("//   ", 0) == 0) {
      listed += line.substr(5);
    } else if (in_list && !listed.empty()) {
      break;
    }
  }
  std::vector<std::string> names;
  std::stringstream ss(listed);
  for (std::string name; std::getline(ss, name, ',');) {
    name.erase(0, name.find_first_not_of(' '));
    name.erase(name.find_last_not_of(' ') + 1);
    names.push_back(name);
  }
  EXPECT_EQ(names, render::frame_log_columns());
}

TEST(FrameLog, BadInputNamesTheLineAndColumn) {
  auto csv = render::frame_log_csv(series(2, 0.1));
  auto bad_header = render::parse_frame_log("frame,time\n1,2\n", "x.csv");
  ASSERT_FALSE(bad_header.ok());
  EXPECT_NE(bad_header.error().message.find("x.csv: line 1"), std::string::npos);
  const size_t second = csv.find('\n', csv.find('\n') + 1) + 1;  // start of the second data row
  std::string broken = csv;
  broken[second] = 'z';  // frame index "z"
  auto bad_field = render::parse_frame_log(broken, "x.csv");
  ASSERT_FALSE(bad_field.ok());
  EXPECT_NE(bad_field.error().message.find("line 3: column frame"), std::string::npos) << bad_field.error().message;
  std::string extended = csv;
  extended += "1,2\n";
  auto short_row = render::parse_frame_log(extended, "x.csv");
  ASSERT_FALSE(short_row.ok());
  EXPECT_NE(short_row.error().message.find("line 4"), std::string::npos);
}

// The parts of the frames that make the p99: 101 frames (frame 0 left out: 100), two slow ones (the p99 by
// nearest rank is the 99th of 100: the quicker of the two), each part averaged over them.
TEST(PathAnalysis, SlowestFramesPartsAreTheMeanOverThoseAtOrAboveTheP99) {
  auto v = series(101, 1.0 / 30);
  for (auto& f : v) {
    f.latency_ms = 3.0;
    f.gpu_ms = 2.0;
    f.plan_ms = 1.0;
  }
  v[0].latency_ms = 100.0;  // start-up: left out
  v[50].latency_ms = 8.0;
  v[50].gpu_ms = 4.0;
  v[50].intake_ms = 1.0;
  v[50].bind_ms = 2.0;
  v[50].mips = 500;
  v[90].latency_ms = 6.0;
  v[90].gpu_ms = 3.0;
  v[90].intake_ms = 2.0;
  v[90].mips = 300;
  const RunAnalysis a = analyse_run(v, 1.0 / 30, {});
  EXPECT_EQ(a.p99_latency_ms, 6.0);
  EXPECT_EQ(a.slowest.frames, 2u);
  EXPECT_DOUBLE_EQ(a.slowest.latency, 7.0);
  EXPECT_DOUBLE_EQ(a.slowest.gpu, 3.5);
  EXPECT_DOUBLE_EQ(a.slowest.intake, 1.5);
  EXPECT_DOUBLE_EQ(a.slowest.bind, 1.0);
  EXPECT_DOUBLE_EQ(a.slowest.plan, 1.0);
  EXPECT_DOUBLE_EQ(a.slowest.mips, 400.0);
  EXPECT_EQ(a.all.frames, 100u);
  EXPECT_DOUBLE_EQ(a.all.latency, (98 * 3.0 + 14.0) / 100);
}

TEST(PathAnalysis, Stat3SkipsNaN) {
  const Stat3 s = stat3({3, kNaN, 1, 2, 10});
  EXPECT_EQ(s.samples, 4u);
  EXPECT_DOUBLE_EQ(s.median, 2.5);
  EXPECT_DOUBLE_EQ(s.avg, 4.0);
  EXPECT_DOUBLE_EQ(s.max, 10.0);
  EXPECT_TRUE(std::isnan(stat3({kNaN}).median));
}

TEST(PathAnalysis, RatesOverWindowsOfWallTime) {
  auto v = series(6, 0.05);  // wall 0.05 .. 0.30
  for (auto& f : v) {
    f.mips = 10;
    f.bytes = 1'000'000;
  }
  const Rates r = windowed_rates(v, 0.10423);
  // Windows close at wall 0.15 (3 frames over 0.15 s) and 0.30 (3 frames over 0.15 s).
  ASSERT_EQ(r.mips_per_s.size(), 2u);
  EXPECT_NEAR(r.mips_per_s[0], 30 / 0.15, 1e-9);
  EXPECT_NEAR(r.mb_per_s[1], 3 / 0.15, 1e-9);
}

TEST(PathAnalysis, RecoveryIsTheFirstFrameWithin1DbOfTheSettledPsnr) {
  // 30 fps; a cut at 2 s; PSNR 20 dB before recovery, then a ramp of 20 dB per second up to 40 dB at 3 s,
  // and 40 dB until the segment ends at 5 s. Within 1 dB: PSNR >= 39 at t = 2.95 s, 0.95 s after the cut.
  auto v = series(150, 1.0 / 30);
  for (auto& f : v) {
    const double t = f.time_s;
    f.psnr_db = t < 2.0 ? 45.0 : std::min(40.0, 20.0 + 20.0 * (t - 2.0));
  }
  const Recovery r = recovery_after_cut(v, 2.0, 5.0);
  EXPECT_DOUBLE_EQ(r.settled_psnr_db, 40.0);
  EXPECT_NEAR(r.seconds, 0.95, 1.0 / 30 + 1e-9);
  EXPECT_GE(r.seconds, 0.95 - 1e-9);
  // A view that never settles within the tolerance of its own end... is by definition reached; one with no
  // frames in the segment is not.
  EXPECT_TRUE(std::isnan(recovery_after_cut(v, 6.0, 7.0).seconds));
  // An immediate recovery (already at the settled level): 0 s.
  for (auto& f : v) f.psnr_db = 33.0;
  EXPECT_DOUBLE_EQ(recovery_after_cut(v, 2.0, 5.0).seconds, 0.0);
}

TEST(PathAnalysis, CutsAndSections) {
  auto path = CameraPath::parse(
      "0 0 0 10 0 -20\n8 0 100 10 0 -20\n10 0 100 10 0 -20\n10 500 0 30 90 -30\n18 600 0 30 90 -30\n", "test");
  ASSERT_TRUE(path.ok());
  const auto cuts = cut_times(*path);
  ASSERT_EQ(cuts.size(), 1u);  // the pause (8 -> 10, same pose) is not a cut
  EXPECT_DOUBLE_EQ(cuts[0], 10.0);
  const CameraPath s = path_section(*path, 8.5, 12.5);
  EXPECT_DOUBLE_EQ(s.duration_s(), 4.0);
  const auto scuts = cut_times(s);
  ASSERT_EQ(scuts.size(), 1u);
  EXPECT_DOUBLE_EQ(scuts[0], 1.5);
  EXPECT_DOUBLE_EQ(s.sample(0.0).position[1], 100.0);   // in the pause
  EXPECT_DOUBLE_EQ(s.sample(4.0).position[0], 531.25);  // 2.5 s into the 8 s move of 100 m
}

TEST(PathAnalysis, AnalysisIntegratesErrorAndFindsPopIn) {
  auto v = series(4, 0.5);
  const double mse[] = {100, 50, 10, 0};
  for (size_t i = 0; i < 4; ++i) {
    v[i].mse = mse[i];
    v[i].ssim = 0.9;
    v[i].psnr_db = 30;
    v[i].latency_ms = static_cast<double>(i + 1);
  }
  v[2].popin_mse = 7;
  v[3].popin_mse = 3;
  const RunAnalysis a = analyse_run(v, 0.5, {});
  EXPECT_DOUBLE_EQ(a.integrated_mse, 80.0);  // (100 + 50 + 10 + 0) * 0.5 s
  EXPECT_NEAR(a.integrated_dssim, 4 * 0.1 * 0.5, 1e-12);
  EXPECT_DOUBLE_EQ(a.max_popin_mse, 7.0);
  EXPECT_EQ(a.popin_frames, 2u);
  EXPECT_DOUBLE_EQ(a.latency_ms.max, 4.0);
  EXPECT_DOUBLE_EQ(a.latency_ms.median, 3.0);  // frames 1-3: frame 0 is warm-up (kWarmUpFrames)
  EXPECT_DOUBLE_EQ(a.p95_latency_ms, 4.0);
}

TEST(PathAnalysis, P99IsTheNearestRankWithoutFrameZero) {
  auto v = series(101, 0.1);
  for (auto& f : v) f.latency_ms = static_cast<double>(f.index);  // frame 0: 0 ms, left out
  v[0].latency_ms = 1000;                                         // a huge warm-up frame changes nothing
  const RunAnalysis a = analyse_run(v, 0.1, {});
  EXPECT_DOUBLE_EQ(a.p95_latency_ms, 95.0);  // latencies 1..100: rank ceil(0.95 * 100)
  EXPECT_DOUBLE_EQ(a.p99_latency_ms, 99.0);
  EXPECT_DOUBLE_EQ(a.latency_ms.max, 100.0);
  EXPECT_DOUBLE_EQ(nearest_rank({5, 1, 3}, 0.99), 5.0);
  EXPECT_TRUE(std::isnan(nearest_rank({}, 0.5)));
}

TEST(PathAnalysis, IntegratedMipDeficitSumsTheMeasuredFrames) {
  auto v = series(5, 0.25);
  const double deficit[] = {kNaN, 4.0, 2.0, 1.0, 0.0};  // no list before frame 1
  for (size_t i = 0; i < 5; ++i) v[i].mip_deficit = deficit[i];
  const RunAnalysis a = analyse_run(v, 0.25, {});
  EXPECT_DOUBLE_EQ(a.integrated_mip_deficit, (4.0 + 2.0 + 1.0) * 0.25);
  EXPECT_EQ(a.mip_deficit.samples, 4u);
  EXPECT_DOUBLE_EQ(a.mip_deficit.max, 4.0);
}

// 30 fps from 0 to 5 s, a cut at 2 s. Before it the old view is in detail (deficit 0, lists read). After
// it, no list is read until 2.1 s (the stale list still says 0), then the deficit falls 1 level per 0.1 s
// from 3 to 0, reached at frame 75 (2.5 s); PSNR ramps 20 dB/s from 20 dB to 40 dB (3 s).
std::vector<FrameRecord> cut_series() {
  constexpr double dt = 1.0 / 30;
  auto v = series(150, dt);
  for (auto& f : v) {
    const double t = f.time_s;
    f.psnr_db = t < 2.0 ? 45.0 : std::min(40.0, 20.0 + 20.0 * (t - 2.0));
    if (t < 2.0 - 1e-9) {
      f.mip_deficit = 0.0;
      f.list_fresh = f.index % 3 == 0;
    } else if (f.index < 63) {  // 2.0 .. 2.1 s: the list of the old view
      f.mip_deficit = 0.0;
    } else {
      f.list_fresh = f.index % 3 == 0;
      f.mip_deficit = std::max(0.0, 3.0 - 10.0 * (t - 2.2));
      if (f.index >= 75) f.mip_deficit = 0.0;
    }
  }
  return v;
}

TEST(PathAnalysis, TimeToDetailWaitsForAListOfTheNewView) {
  constexpr double dt = 1.0 / 30;
  const auto v = cut_series();
  const TimeToDetail d = time_to_detail(v, 2.0, 5.0, dt);
  // Frame 75 (t = 2.5) is the first with deficit 0 after the list of frame 63; frame 76 draws it.
  EXPECT_NEAR(d.deficit_s, 75 * dt + dt - 2.0, 1e-9);
  // PSNR: settled 40 dB, target within 0.5 dB: PSNR >= 39.5 from t = 2.975 s.
  EXPECT_DOUBLE_EQ(d.target_psnr_db, 40.0);
  EXPECT_GE(d.psnr_s, 0.975 - 1e-9);
  EXPECT_LE(d.psnr_s, 0.975 + dt);
  // The looser recovery (1 dB) comes earlier.
  EXPECT_LT(recovery_after_cut(v, 2.0, 5.0).seconds, d.psnr_s);
}

TEST(PathAnalysis, TimeToDetailIsNeverWhenTheDeficitStaysOrNoListComes) {
  constexpr double dt = 1.0 / 30;
  auto v = cut_series();
  for (auto& f : v)
    if (f.time_s >= 2.0 - 1e-9) f.mip_deficit = std::max(f.mip_deficit, 0.5);
  EXPECT_TRUE(std::isnan(time_to_detail(v, 2.0, 5.0, dt).deficit_s));
  auto stale = cut_series();
  for (auto& f : stale)
    if (f.time_s >= 2.0 - 1e-9) f.list_fresh = false;  // deficit 0 all along, but of the old view's list
  EXPECT_TRUE(std::isnan(time_to_detail(stale, 2.0, 5.0, dt).deficit_s));
  // Through analyse_run: one entry per cut inside the run.
  const RunAnalysis a = analyse_run(cut_series(), dt, {2.0, 9.0});
  ASSERT_EQ(a.detail.size(), 1u);
  EXPECT_NEAR(a.detail[0].deficit_s, 76 * dt - 2.0, 1e-9);
}

TEST(PathAnalysis, MedianTimeToDetailCountsNeverAsLongest) {
  auto cut = [](double s) {
    TimeToDetail d;
    d.deficit_s = s;
    return d;
  };
  EXPECT_TRUE(std::isnan(median_time_to_detail({})));
  EXPECT_DOUBLE_EQ(median_time_to_detail({cut(0.5), cut(kNaN), cut(0.2)}), 0.5);
  EXPECT_EQ(median_time_to_detail({cut(kNaN), cut(kNaN), cut(0.2)}), kInf);
  EXPECT_DOUBLE_EQ(median_time_to_detail({cut(0.4), cut(0.2)}), 0.3);
}

TEST(PathAnalysis, HeadlineRatios) {
  EXPECT_DOUBLE_EQ(headline_ratio(3.0, 1.5), 2.0);
  EXPECT_DOUBLE_EQ(headline_ratio(0.0, 0.0), 1.0);
  EXPECT_EQ(headline_ratio(1.0, 0.0), kInf);
  EXPECT_EQ(headline_ratio(kInf, 2.0), kInf);        // the baseline never got there, ours did
  EXPECT_DOUBLE_EQ(headline_ratio(2.0, kInf), 0.0);  // ours never did
  EXPECT_TRUE(std::isnan(headline_ratio(kInf, kInf)));
  EXPECT_TRUE(std::isnan(headline_ratio(kNaN, 1.0)));
  EXPECT_TRUE(std::isnan(headline_ratio(1.0, kNaN)));
}

TEST(PathAnalysis, LockstepDifferenceNamesTheFirstDifferingFrameAndColumn) {
  auto a = series(5, 0.1), b = series(5, 0.1);
  b[3].latency_ms = 99;  // wall-clock quantities may differ
  b[3].wall_s = 42;
  EXPECT_EQ(lockstep_difference(a, b), "");
  b[3].ssim = 0.5;
  EXPECT_EQ(lockstep_difference(a, b), "frame 3: ssim");
  b[2].mips = 1;
  EXPECT_EQ(lockstep_difference(a, b), "frame 2: mips");
  b[1].mip_deficit = 0.5;
  EXPECT_EQ(lockstep_difference(a, b), "frame 1: mip_deficit");
  b[0].wasted_bytes = 1;
  EXPECT_EQ(lockstep_difference(a, b), "frame 0: wasted_bytes");
  EXPECT_NE(lockstep_difference(a, series(4, 0.1)), "");
}

}  // namespace
}  // namespace texstream::bench
