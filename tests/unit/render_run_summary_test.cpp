#include <gtest/gtest.h>

#include "texstream/render/measure/run_summary.hpp"

using namespace texstream;

// The run summary's tally of textures given up on: the count and the first few ids, in text and JSON.
TEST(RunSummaryTally, NamesTheFirstFewTexturesAndCountsThemAll) {
  render::RunSummary s;
  s.textures_refused = render::TextureTally::of({11, 4, 9, 30, 2, 7, 8});
  s.textures_quarantined = render::TextureTally::of({5});
  const std::string text = s.to_text();
  EXPECT_NE(text.find("7 refused (textures 11, 4, 9, 30, 2, ...)"), std::string::npos) << text;
  EXPECT_NE(text.find("0 charged with a server death, 1 quarantined (texture 5)"), std::string::npos) << text;
  const std::string json = s.to_json();
  EXPECT_NE(json.find("\"textures_refused\": {\n    \"count\": 7"), std::string::npos) << json;
}
