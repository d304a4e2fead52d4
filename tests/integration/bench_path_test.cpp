// texstream-bench path --quick on a generated 300-texture RGBA8 scene.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "../support/shell_command.hpp"

namespace fs = std::filesystem;

namespace {

const fs::path kBin = TEXSTREAM_BIN_DIR;

using texstream::test::last_line;
using texstream::test::run_command;

class BenchPath : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    work_ = fs::temp_directory_path() / ("texstream-bench-path-" + std::to_string(::getpid()));
    fs::remove_all(work_);
    fs::create_directories(work_);
    gen_rc_ = run_command((kBin / "texstream-gen").string() + " --out " + (work_ / "scene").string() +
                              " --textures 300 --seed 5 --format rgba8 --threads 2",
                          nullptr);
    if (gen_rc_ == 0) {
      bench_rc_ = run_command((kBin / "texstream-bench").string() + " path --quick --scene " +
                                  (work_ / "scene").string() + " --out " + (work_ / "out").string(),
                              &bench_output_);
    }
  }
  static void TearDownTestSuite() { fs::remove_all(work_); }
  static fs::path work_;
  static int gen_rc_, bench_rc_;
  static std::string bench_output_;
};
fs::path BenchPath::work_;
int BenchPath::gen_rc_ = -1, BenchPath::bench_rc_ = -1;
std::string BenchPath::bench_output_;

TEST_F(BenchPath, QuickRunWritesTheSummaryLineAndReport) {
  ASSERT_EQ(gen_rc_, 0);
  ASSERT_EQ(bench_rc_, 0) << bench_output_;
  const std::string summary = last_line(bench_output_);
  EXPECT_EQ(summary.rfind("summary: lockstep_identical=true max_latency_ratio=", 0), 0u) << summary;
  // The keys in their order (tooling reads them; issue 25 appended the last five).
  size_t at = 0;
  for (const char* key : {"popin_ratio=", "integrated_error_ratio=", "streaming_overhead=", "process_boundary_cost=",
                          "time_to_detail_ratio=", "mip_deficit_ratio=", "p99_latency_ratio=",
                          "resident_blend_psnr_db=", "wasted_bytes_frac="}) {
    const size_t found = summary.find(key, at);
    EXPECT_NE(found, std::string::npos) << key << " missing or out of order: " << summary;
    if (found != std::string::npos) at = found;
  }
  // Every value measured, except that time_to_detail_ratio is NaN when neither run's deficit reached 0 after
  // the cut: the quick section's camera moves on after its cut, and a moving view keeps wanting finer levels a
  // cycle ahead of what has arrived (docs/design/stream_metrics.md).
  std::string others = summary;
  const size_t ttd = others.find("time_to_detail_ratio=");
  if (ttd != std::string::npos) others.erase(ttd, others.find(' ', ttd) - ttd);
  EXPECT_EQ(others.find("nan"), std::string::npos) << summary;
  EXPECT_TRUE(fs::exists(work_ / "out" / "plots" / "mip_deficit.png"));
  EXPECT_TRUE(fs::exists(work_ / "out" / "report.md"));
  EXPECT_TRUE(fs::exists(work_ / "out" / "plots" / "pareto.png"));
  EXPECT_TRUE(fs::exists(work_ / "out" / "raw" / "ours.csv"));
}

TEST_F(BenchPath, ResidentRunReproducesTheReferenceAndStreamingDoesNot) {
  ASSERT_EQ(bench_rc_, 0) << bench_output_;
  std::ifstream in(work_ / "out" / "results.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  std::map<std::string, nlohmann::json> runs;
  for (const auto& r : j["runs"]) runs[r["name"].get<std::string>()] = r;
  for (const char* name :
       {"reference", "ours", "baseline", "seed", "resident_blend", "inprocess", "lockstep_a", "lockstep_b"}) {
    ASSERT_TRUE(runs.count(name)) << name;
    EXPECT_EQ(runs[name]["exit_code"], 0) << name;
    EXPECT_EQ(runs[name]["failure"], "") << name;
  }
  // Every texture resident with the default (converging) blend: the same pixels as the reference, frame for
  // frame (PSNR capped at 100 dB, SSIM 1): the blend is exact at the wanted level.
  EXPECT_DOUBLE_EQ(runs["resident_blend"]["psnr_db"]["median"].get<double>(), 100.0);
  EXPECT_DOUBLE_EQ(runs["resident_blend"]["integrated_mse"].get<double>(), 0.0);
  EXPECT_DOUBLE_EQ(j["summary"]["resident_blend_psnr_db"].get<double>(), 100.0);
  // Streaming starts from the colormap: some error, which refinement then lowers.
  EXPECT_GT(runs["ours"]["integrated_mse"].get<double>(), 0.0);
  EXPECT_GT(runs["ours"]["mse"]["max"].get<double>(), runs["ours"]["mse"]["median"].get<double>());
  // The seed's Eq. 8 keeps mixing the colormap in at a coarse displayed level: more error than ours.
  EXPECT_GT(runs["seed"]["integrated_mse"].get<double>(), 0.0);
  // The quick path holds one cut, whose recovery is measured.
  EXPECT_EQ(j["cuts_s"].size(), 1u);
  EXPECT_EQ(runs["ours"]["recoveries"].size(), 1u);
  EXPECT_EQ(runs["ours"]["time_to_detail"].size(), 1u);
  EXPECT_TRUE(j["summary"]["lockstep_identical"].get<bool>()) << j["summary"]["lockstep_difference"];
}

TEST_F(BenchPath, MipDeficitIsZeroWithEverythingResidentAndNotWhileStreaming) {
  ASSERT_EQ(bench_rc_, 0) << bench_output_;
  std::ifstream in(work_ / "out" / "results.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  std::map<std::string, nlohmann::json> runs;
  for (const auto& r : j["runs"]) runs[r["name"].get<std::string>()] = r;
  // Every mip of every texture resident before frame 0: each listed texture is drawn at its wanted level.
  EXPECT_GT(runs["resident_blend"]["mip_deficit"]["samples"].get<uint64_t>(), 0u);
  EXPECT_DOUBLE_EQ(runs["resident_blend"]["mip_deficit"]["max"].get<double>(), 0.0);
  EXPECT_DOUBLE_EQ(runs["resident_blend"]["integrated_mip_deficit"].get<double>(), 0.0);
  // Streaming starts with nothing resident: a deficit, integrated over the run.
  EXPECT_GT(runs["ours"]["mip_deficit"]["max"].get<double>(), 0.0);
  EXPECT_GT(runs["baseline"]["integrated_mip_deficit"].get<double>(), 0.0);
  // The preload streams the whole scene, most of which this short path never shows.
  const double resident_waste = runs["resident_blend"]["wasted_bytes_frac"].get<double>();
  EXPECT_GT(resident_waste, 0.0);
  EXPECT_LE(resident_waste, 1.0);
  const double ours_waste = j["summary"]["wasted_bytes_frac"].get<double>();
  EXPECT_GE(ours_waste, 0.0);
  EXPECT_LT(ours_waste, resident_waste);
}

TEST(BenchPathArguments, UnknownArgumentAndMissingSceneAreRefused) {
  std::string out;
  EXPECT_EQ(run_command((kBin / "texstream-bench").string() + " path --bogus", &out), 2) << out;
  EXPECT_NE(out.find("--bogus"), std::string::npos);
  EXPECT_EQ(run_command((kBin / "texstream-bench").string() +
                            " path --quick --scene /nonexistent-scene-dir --out /tmp/x" + std::to_string(::getpid()),
                        &out),
            2)
      << out;
  EXPECT_NE(out.find("/nonexistent-scene-dir"), std::string::npos);
}

}  // namespace
