// Content-Range parsing and the check of a 206 answer against the asked range (http origin, issue 4).
#include <gtest/gtest.h>

#include "texstream/server/storage/content_range.hpp"

namespace texstream::server {
namespace {

TEST(ContentRange, ParsesRangeAndLength) {
  auto r = parse_content_range(" bytes 100-199/1000\r\n");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(*r->first, 100u);
  EXPECT_EQ(*r->last, 199u);
  EXPECT_EQ(*r->total, 1000u);
}

TEST(ContentRange, ParsesUnknownLengthAndUnsatisfiedRange) {
  auto unknown = parse_content_range("bytes 0-9/*");
  ASSERT_TRUE(unknown.ok());
  EXPECT_FALSE(unknown->total.has_value());
  auto unsatisfied = parse_content_range("bytes */42");
  ASSERT_TRUE(unsatisfied.ok());
  EXPECT_FALSE(unsatisfied->first.has_value());
  EXPECT_EQ(*unsatisfied->total, 42u);
}

TEST(ContentRange, RejectsMalformedValues) {
  for (const char* bad : {"", "bytes", "items 0-1/2", "bytes 0-1", "bytes 5-1/10", "bytes 0-10/10", "bytes a-b/10",
                          "bytes 0-1/x", "bytes */*", "bytes 0-/10", "bytes -5/10", "bytes 1-2-3/10"}) {
    auto r = parse_content_range(bad);
    EXPECT_FALSE(r.ok()) << "'" << bad << "' was accepted";
    if (!r.ok()) {
      EXPECT_EQ(r.error().code, ErrorCode::kCorrupt);
    }
  }
}

TEST(ContentRange, AcceptsExactlyTheAskedRange) {
  auto n = check_range_answer(*parse_content_range("bytes 128-255/1000"), 128, 128, "u");
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(*n, 128u);
}

TEST(ContentRange, AcceptsAShorterAnswerOnlyWhereTheObjectEnds) {
  // Asked 0-147 of a 100-byte object (a DDS header read of a tiny file).
  auto ends = check_range_answer(*parse_content_range("bytes 0-99/100"), 0, 148, "u");
  ASSERT_TRUE(ends.ok());
  EXPECT_EQ(*ends, 100u);
  EXPECT_FALSE(check_range_answer(*parse_content_range("bytes 0-99/1000"), 0, 148, "u").ok());
  EXPECT_FALSE(check_range_answer(*parse_content_range("bytes 0-99/*"), 0, 148, "u").ok());
}

TEST(ContentRange, RejectsShiftedLongerOrMissingRangesNamingTheUrl) {
  auto shifted = check_range_answer(*parse_content_range("bytes 129-256/1000"), 128, 128, "http://o/t.dds");
  ASSERT_FALSE(shifted.ok());
  EXPECT_NE(shifted.error().message.find("http://o/t.dds"), std::string::npos);
  EXPECT_NE(shifted.error().message.find("asked bytes 128-255"), std::string::npos);
  EXPECT_FALSE(check_range_answer(*parse_content_range("bytes 128-300/1000"), 128, 128, "u").ok());
  EXPECT_FALSE(check_range_answer(*parse_content_range("bytes */1000"), 128, 128, "u").ok());
  EXPECT_FALSE(check_range_answer(*parse_content_range("bytes 0-0/1"), 0, 0, "u").ok());
}

}  // namespace
}  // namespace texstream::server
