// Camera paths: parsing (comments, errors naming file and line), interpolation, cuts, pauses, clamping.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <fstream>

#include "texstream/common/camera_path.hpp"

using namespace texstream;

namespace {

CameraPath parse_ok(const std::string& text) {
  auto r = CameraPath::parse(text, "test.txt");
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
  return r.ok() ? std::move(r).value() : CameraPath({});
}

void expect_parse_error(const std::string& text, const std::string& needle) {
  auto r = CameraPath::parse(text, "path.txt");
  ASSERT_FALSE(r.ok()) << "accepted: " << text;
  EXPECT_NE(r.error().message.find(needle), std::string::npos) << r.error().message;
  EXPECT_EQ(r.error().message.rfind("path.txt", 0), 0u) << r.error().message;
}

}  // namespace

TEST(CameraPath, ParsesKeysCommentsAndBlankLines) {
  const CameraPath p = parse_ok(
      "# header\n"
      "\n"
      "0 392000 5820000 80 45 -30   # start\n"
      "  \t\n"
      "2.5\t392100.5 5820000 80 90 -30\r\n"
      "4 392100.5 5820000 80 90 -30");
  ASSERT_EQ(p.keys().size(), 3u);
  EXPECT_DOUBLE_EQ(p.keys()[1].time_s, 2.5);
  EXPECT_DOUBLE_EQ(p.keys()[1].pose.position[0], 392100.5);
  EXPECT_DOUBLE_EQ(p.keys()[0].pose.yaw_deg, 45);
  EXPECT_DOUBLE_EQ(p.keys()[0].pose.pitch_deg, -30);
  EXPECT_DOUBLE_EQ(p.duration_s(), 4);
}

TEST(CameraPath, ErrorsNameFileAndLine) {
  expect_parse_error("0 1 2 3 4 5\n1 1 2 3 4\n", "path.txt:2:");
  expect_parse_error("0 1 2 3 4 5\n\n# c\n1 1 2 3 4 5 6\n", "path.txt:4:");
  expect_parse_error("0 1 2 x 4 5\n", "'z'");
  expect_parse_error("0 1 2 3 nan 5\n", "yaw_deg");
  expect_parse_error("0 1 2 3 4 5\n2 1 2 3 4 5\n1 1 2 3 4 5\n", "path.txt:3: time_s goes backwards");
  expect_parse_error("0 1 2 3 4 95\n", "pitch_deg");
  expect_parse_error("-1 1 2 3 4 5\n", "negative");
  expect_parse_error("# only a comment\n", "no keyframes");
  expect_parse_error("", "no keyframes");
  expect_parse_error("0 1 2 3 4 5x\n", "pitch_deg");
}

TEST(CameraPath, LoadReadsFileAndReportsMissing) {
  const auto file =
      std::filesystem::temp_directory_path() / ("texstream_camera_path_" + std::to_string(::getpid()) + ".txt");
  std::ofstream(file) << "0 1 2 3 0 0\n1 2 2 3 0 0\n";
  auto p = CameraPath::load(file);
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_EQ(p->keys().size(), 2u);
  std::filesystem::remove(file);
  auto missing = CameraPath::load(file);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
  EXPECT_NE(missing.error().message.find(file.string()), std::string::npos);
}

TEST(CameraPath, InterpolatesLinearlyAndClamps) {
  const CameraPath p = parse_ok("1 100 200 50 0 -10\n3 300 0 70 0 -30\n");
  const CameraPose mid = p.sample(2.0);
  EXPECT_DOUBLE_EQ(mid.position[0], 200);
  EXPECT_DOUBLE_EQ(mid.position[1], 100);
  EXPECT_DOUBLE_EQ(mid.position[2], 60);
  EXPECT_DOUBLE_EQ(mid.pitch_deg, -20);
  const CameraPose q = p.sample(1.5);
  EXPECT_DOUBLE_EQ(q.position[0], 150);
  // Outside the keyed range the pose holds at the nearest end.
  EXPECT_DOUBLE_EQ(p.sample(-5).position[0], 100);
  EXPECT_DOUBLE_EQ(p.sample(0.999).position[0], 100);
  EXPECT_DOUBLE_EQ(p.sample(3).position[0], 300);
  EXPECT_DOUBLE_EQ(p.sample(1e9).position[0], 300);
}

TEST(CameraPath, YawTakesTheShorterArc) {
  const CameraPath p = parse_ok("0 0 0 0 350 0\n1 0 0 0 10 0\n2 0 0 0 -170 0\n3 0 0 0 170 0\n");
  // 350 -> 10 goes through 360, not back through 180.
  const double y1 = p.sample(0.5).yaw_deg;
  EXPECT_NEAR(std::remainder(y1, 360.0), 0.0, 1e-9);
  // 10 -> -170 is exactly half a turn: either way is 180 degrees; the mid yaw is 10 +- 90.
  const double y2 = std::remainder(p.sample(1.5).yaw_deg, 360.0);
  EXPECT_NEAR(std::abs(y2 - 10.0), 90.0, 1e-9);
  // -170 -> 170 crosses 180 (20 degrees), not 0 (340 degrees).
  EXPECT_NEAR(std::abs(std::remainder(p.sample(2.5).yaw_deg, 360.0)), 180.0, 1e-9);
  EXPECT_NEAR(std::remainder(p.sample(2.25).yaw_deg - (-175.0), 360.0), 0.0, 1e-9);
}

TEST(CameraPath, EqualTimesCutAndRepeatedKeysPause) {
  const CameraPath p = parse_ok(
      "0 0 0 0 0 0\n"
      "2 100 0 0 0 0\n"  // pause: the same pose at t = 2 and t = 4
      "4 100 0 0 0 0\n"
      "4 5000 0 0 90 0\n"  // cut at t = 4 to a new view
      "6 5100 0 0 90 0\n");
  EXPECT_DOUBLE_EQ(p.sample(3).position[0], 100);
  EXPECT_DOUBLE_EQ(p.sample(3.999999).position[0], 100);
  EXPECT_DOUBLE_EQ(p.sample(4).position[0], 5000);  // from the cut time on: the new view
  EXPECT_DOUBLE_EQ(p.sample(4).yaw_deg, 90);
  EXPECT_DOUBLE_EQ(p.sample(5).position[0], 5050);
  EXPECT_DOUBLE_EQ(p.sample(1).position[0], 50);
}

TEST(CameraPath, ToTextRoundTripsExactly) {
  const CameraPath p({CameraKey{0, CameraPose{{392000.123456789, 5820000.000001, 42.1}, 33.3, -25.7}},
                      CameraKey{1.0 / 3.0, CameraPose{{1e-17, -0.0, 1e300}, -720.5, 90}}});
  auto back = CameraPath::parse(p.to_text(), "roundtrip");
  ASSERT_TRUE(back.ok()) << back.error().message;
  ASSERT_EQ(back->keys().size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(back->keys()[i].time_s, p.keys()[i].time_s);
    for (int a = 0; a < 3; ++a) EXPECT_EQ(back->keys()[i].pose.position[a], p.keys()[i].pose.position[a]);
    EXPECT_EQ(back->keys()[i].pose.yaw_deg, p.keys()[i].pose.yaw_deg);
    EXPECT_EQ(back->keys()[i].pose.pitch_deg, p.keys()[i].pose.pitch_deg);
  }
}
