// texstream-bench pages end to end on a small painted ground: the summary line's keys in their order, seams 0
// (pages drawn with all resident equal the ordinary mipmapped texture), exact page reads, one CSV row per
// configuration, budget and frame, lock-step runs identical; a page file the bench cannot draw is named.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "../support/shell_command.hpp"

namespace fs = std::filesystem;

namespace {

const fs::path kBin = TEXSTREAM_BIN_DIR;

using texstream::test::last_line;
using texstream::test::run_command;

std::map<std::string, std::string> fields(const std::string& summary, std::vector<std::string>* order) {
  std::map<std::string, std::string> out;
  std::istringstream in(summary.substr(summary.find(':') + 1));
  std::string kv;
  while (in >> kv) {
    const auto eq = kv.find('=');
    out[kv.substr(0, eq)] = kv.substr(eq + 1);
    order->push_back(kv.substr(0, eq));
  }
  return out;
}

std::string bench(const fs::path& out) {
  return (kBin / "texstream-bench").string() +
         " pages --quick --ground 1024 --metres-per-texel 0.1 --width 96 --height 64 --out " + out.string();
}

TEST(BenchPages, SummaryHasNoSeamsExactReadsAndOneRowPerFrame) {
  const fs::path work = fs::temp_directory_path() / ("texstream-bench-pages-" + std::to_string(::getpid()));
  fs::remove_all(work);
  std::string output, again;
  ASSERT_EQ(run_command(bench(work / "a"), &output), 0) << output;
  const std::string summary = last_line(output);
  ASSERT_EQ(summary.rfind("summary: ", 0), 0u) << summary;
  std::vector<std::string> order;
  const auto f = fields(summary, &order);
  EXPECT_EQ(order, (std::vector<std::string>{"heuristics", "best", "best_vs_random_ssim", "lookahead_gain",
                                             "extern_uniformity", "seams_max_abs_diff", "page_read_amp"}));
  EXPECT_EQ(f.at("heuristics"), "14");
  // The larger of the CPU sampler's seams (exactly 0: the same arithmetic both ways) and the GPU's (lavapipe's
  // filtering: 1), each printed on its own line.
  EXPECT_LE(std::stod(f.at("seams_max_abs_diff")), 2.0) << "pages with all resident differ from the mipmapped texture";
  EXPECT_NE(output.find("seams on the GPU (llvmpipe"), std::string::npos) << output;
  EXPECT_NE(output.find("on the CPU: 0\n"), std::string::npos) << output;
  EXPECT_GE(std::stod(f.at("page_read_amp")), 1.0);
  EXPECT_LE(std::stod(f.at("page_read_amp")), 1.1);
  EXPECT_GT(std::stod(f.at("best_vs_random_ssim")), 0.0);
  // 14 configurations x 2 budgets x the path's frames, each with finite values.
  std::ifstream csv(work / "a" / "pages_frames.csv");
  std::string line;
  size_t rows = 0;
  std::getline(csv, line);
  EXPECT_EQ(line, "config,budget,frame,rmse,ssim,wssim,level_spread");
  while (std::getline(csv, line)) {
    ++rows;
    EXPECT_EQ(line.find("nan"), std::string::npos) << line;
  }
  EXPECT_GT(rows, 0u);
  EXPECT_EQ(rows % 28, 0u);
  // Lock-step: a second run prints the same tables and summary.
  ASSERT_EQ(run_command(bench(work / "b"), &again), 0) << again;
  EXPECT_EQ(last_line(again), summary);
  auto tables = [](const std::string& o) {
    const auto from = o.find("pages per frame");
    return o.substr(from, o.find("\nframes:") - from);
  };
  EXPECT_EQ(tables(again), tables(output));
  fs::remove_all(work);
}

TEST(BenchPages, ABlockCompressedPageFileIsNamed) {
  const fs::path work = fs::temp_directory_path() / ("texstream-bench-pages-bc1-" + std::to_string(::getpid()));
  fs::remove_all(work);
  fs::create_directories(work);
  std::string output;
  ASSERT_EQ(run_command((kBin / "texstream-tile").string() + " --paint 256 --format bc1 --quiet --out " +
                            (work / "g.tspages").string(),
                        &output),
            0)
      << output;
  EXPECT_NE(run_command((kBin / "texstream-bench").string() + " pages --quick --file " + (work / "g.tspages").string() +
                            " --out " + (work / "out").string(),
                        &output),
            0);
  EXPECT_NE(output.find((work / "g.tspages").string() + " is bc1"), std::string::npos) << output;
  fs::remove_all(work);
}

}  // namespace
