// Maneuver CSV: parsing, interpolation, and refusal of malformed files with line and reason.
#include <cmath>
#include <filesystem>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "test_support.h"
#include "vdyn/base/limits.h"
#include "vdyn/io/maneuver.h"

namespace vdyn {
namespace {

using ::testing::HasSubstr;
constexpr double kDeg = std::numbers::pi / 180.0;

TEST(Maneuver, InterpolatesLinearlyBetweenRows) {
  const Maneuver m = Maneuver::Parse(
      "t_s,steer_deg,throttle,brake,cruise_kmh\n"
      "0,0,0,0,\n"
      "2,10,1,0,36\n"
      "4,-10,0,0.5,72\n",
      "m.csv");
  ASSERT_EQ(m.rows().size(), 3u);
  EXPECT_DOUBLE_EQ(m.end_time(), 4.0);
  const ManeuverInput a = m.At(1.0);
  EXPECT_NEAR(a.steer, 5.0 * kDeg, 1e-15);
  EXPECT_DOUBLE_EQ(a.throttle, 0.5);
  EXPECT_FALSE(a.cruise_on);  // the row before t has cruise off
  const ManeuverInput b = m.At(3.0);
  EXPECT_NEAR(b.steer, 0.0, 1e-15);
  EXPECT_DOUBLE_EQ(b.brake, 0.25);
  EXPECT_TRUE(b.cruise_on);
  EXPECT_NEAR(b.cruise_speed, 15.0, 1e-12);  // halfway between 10 and 20 m/s
  EXPECT_DOUBLE_EQ(m.At(-1.0).throttle, 0.0);  // before the first row
  EXPECT_NEAR(m.At(99.0).steer, -10.0 * kDeg, 1e-15);  // after the last
}

TEST(Maneuver, ColumnsInAnyOrderCommentsBlankLinesAndCrlf) {
  const Maneuver m = Maneuver::Parse(
      "# comment\r\nbrake, t_s ,throttle,steer_deg\r\n\r\n0,0,0.5,1\r\n0.2,1,0.5,1\r\n", "m.csv");
  ASSERT_EQ(m.rows().size(), 2u);
  EXPECT_DOUBLE_EQ(m.At(0.5).brake, 0.1);
  EXPECT_FALSE(m.At(0.5).cruise_on);
}

TEST(Maneuver, DemoParses) {
  const Maneuver m = Maneuver::Parse(DemoManeuverCsv(), "demo");
  EXPECT_GT(m.end_time(), 30.0);
}

struct BadCase {
  const char* text;
  const char* message;
};

class ManeuverRejects : public ::testing::TestWithParam<BadCase> {};

TEST_P(ManeuverRejects, WithLineAndReason) {
  try {
    Maneuver::Parse(GetParam().text, "m.csv");
    FAIL() << "expected ManeuverError";
  } catch (const ManeuverError& e) {
    EXPECT_THAT(e.what(), HasSubstr(GetParam().message));
  }
}

INSTANTIATE_TEST_SUITE_P(
    Malformed, ManeuverRejects,
    ::testing::Values(
        BadCase{"", "m.csv: empty maneuver"},
        BadCase{"t_s,steer_deg,throttle,brake,cruise_kmh\n", "header but no rows"},
        BadCase{"t_s,steer_deg,throttle\n0,0,0\n", "m.csv:1: missing column 'brake'"},
        BadCase{"t_s,steer,throttle,brake\n", "m.csv:1: unknown column 'steer'"},
        BadCase{"t_s,t_s,steer_deg,throttle,brake\n", "appears twice"},
        BadCase{"t_s,steer_deg,throttle,brake\n0,0,0,0\n1,abc,0,0\n",
                "m.csv:3: column 'steer_deg': 'abc' is not a finite number"},
        BadCase{"t_s,steer_deg,throttle,brake\n0,0,0,nan\n", "column 'brake': 'nan'"},
        BadCase{"t_s,steer_deg,throttle,brake\n0,0,0,1.5\n",
                "m.csv:2: column 'brake': 1.5 is outside [0, 1]"},
        BadCase{"t_s,steer_deg,throttle,brake\n0,0,2,0\n", "column 'throttle': 2 is outside"},
        BadCase{"t_s,steer_deg,throttle,brake,cruise_kmh\n0,0,0,0,-5\n", "column 'cruise_kmh'"},
        BadCase{"t_s,steer_deg,throttle,brake\n0,0,0,0\n0,0,0,0\n",
                "m.csv:3: column 't_s': 0 does not increase"},
        BadCase{"t_s,steer_deg,throttle,brake\n0,0,0\n", "m.csv:2: expected 4 fields, found 3"},
        BadCase{"t_s,steer_deg,throttle,brake\n0,,0,0\n", "column 'steer_deg': empty value"},
        BadCase{"t_s,steer_deg,throttle,brake\n0,0,0,0 1\n", "'0 1' is not a finite number"}));

TEST(Maneuver, MissingFileIsAClearError) {
  try {
    Maneuver::Load("/nonexistent/m.csv");
    FAIL() << "expected ManeuverError";
  } catch (const ManeuverError& e) {
    EXPECT_THAT(e.what(), HasSubstr("/nonexistent/m.csv: no such maneuver file"));
  }
}

// A maneuver is bounded (vdyn/base/limits.h, docs/formats.md): a file larger than a maneuver may be
// is refused before it is read, and the rows beyond the limit at the line where they start
// (issue 20: ten million rows took 1.38 GB). The file is read line by line, not as a whole.
TEST(Maneuver, AFileOrRowCountBeyondTheLimitIsRefused) {
  testing::TempDir dir;
  const auto big = dir / "big.csv";
  {
    testing::WriteFile(big, "t_s,steer_deg,throttle,brake\n0,0,0,0\n");
    // Sparse: the size is all that is looked at.
    std::filesystem::resize_file(big, limits::kMaxManeuverBytes + 1);
  }
  try {
    Maneuver::Load(big);
    FAIL() << "a file over the size limit was read";
  } catch (const ManeuverError& e) {
    EXPECT_THAT(e.what(), HasSubstr(big.string() + ": 67108865 bytes, more than a maneuver file "
                                                   "may hold (67108864 bytes"));
  }
  std::string text = "t_s,steer_deg,throttle,brake\n";
  text.reserve(limits::kMaxManeuverRows * 12);
  for (std::size_t i = 0; i <= limits::kMaxManeuverRows; ++i) {
    text += std::to_string(i) + ",0,0,0\n";
  }
  const auto rows = dir / "rows.csv";
  testing::WriteFile(rows, text);
  try {
    Maneuver::Load(rows);
    FAIL() << "more rows than the limit were read";
  } catch (const ManeuverError& e) {
    EXPECT_THAT(e.what(), HasSubstr(rows.string() + ":1000002: more than 1000000 rows"));
  }
  // At the limit: read.
  text.resize(text.rfind(std::to_string(limits::kMaxManeuverRows) + ",0,0,0\n"));
  testing::WriteFile(rows, text);
  EXPECT_EQ(Maneuver::Load(rows).rows().size(), limits::kMaxManeuverRows);
}

}  // namespace
}  // namespace vdyn
