// texstream-bench plan end to end: the summary line's keys in their order, the fused pass equal to the two passes
// on every view (mismatches=0, exit 0), below and above the 50 000 ids at which the tests go parallel (200 000
// meshes: ~67 000 in the wide frustum); a scene folder that cannot be opened is named.
#include <gtest/gtest.h>

#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "../support/shell_command.hpp"

namespace fs = std::filesystem;

namespace {

const fs::path kBin = TEXSTREAM_BIN_DIR;

using texstream::test::last_line;
using texstream::test::run_command;

TEST(BenchPlan, TheSummaryHasItsKeysAndOnePassEqualsTwo) {
  for (const char* meshes : {"4000", "200000"}) {
    std::string out;
    const int rc =
        run_command((kBin / "texstream-bench").string() + " plan --quick --views 12 --meshes " + meshes, &out);
    ASSERT_EQ(rc, 0) << out;
    const std::string summary = last_line(out);
    ASSERT_EQ(summary.rfind("summary: ", 0), 0u) << out;
    std::istringstream in(summary.substr(9));
    std::vector<std::string> keys;
    std::string kv, mismatches, ids;
    while (in >> kv) {
      const auto eq = kv.find('=');
      keys.push_back(kv.substr(0, eq));
      if (keys.back() == "mismatches") mismatches = kv.substr(eq + 1);
      if (keys.back() == "ids_per_view") ids = kv.substr(eq + 1);
    }
    EXPECT_EQ(keys, (std::vector<std::string>{"meshes", "ids_per_view", "query_ms", "two_pass_ms", "fused_ms",
                                              "fused_speedup", "mismatches"}));
    EXPECT_EQ(mismatches, "0") << summary;
    EXPECT_GT(std::stod(ids), 0.0) << summary;  // the views see the city
  }
}

TEST(BenchPlan, ASceneThatCannotBeOpenedIsNamed) {
  std::string out;
  const int rc = run_command((kBin / "texstream-bench").string() + " plan --quick --scene /nonexistent/city", &out);
  EXPECT_NE(rc, 0);
  EXPECT_NE(out.find("/nonexistent/city"), std::string::npos) << out;
}

}  // namespace
