// Vehicle parameters: defaults, validation with field and reason, files, dump round trip.
#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

#include "vdyn/bridge/params.h"
#include "test_support.h"

namespace vdyn {
namespace {

using ::testing::HasSubstr;
using testing::TempDir;
using testing::WriteFile;

bool HasIssue(const std::vector<ParamIssue>& issues, const std::string& field,
              const std::string& reason_part) {
  for (const auto& i : issues) {
    if (i.field == field && i.reason.find(reason_part) != std::string::npos) return true;
  }
  return false;
}

TEST(Params, DefaultsAreValidAndComplete) {
  const pb::VehicleParams d = DefaultVehicleParams();
  EXPECT_TRUE(ValidateVehicleParams(d).empty()) << FormatIssues(ValidateVehicleParams(d));
  const Params p = ParamsFromProto(d);
  EXPECT_DOUBLE_EQ(p.wheelbase, p.b + p.c);
  // Mount points follow Fig. 4: LF at (+b, +bL), RR at (-c, -bP), z_offset below T.
  EXPECT_EQ(p.p_TA_B[kLF], Eigen::Vector3d(p.b, p.b_l, -p.wheel[kLF].z_offset));
  EXPECT_EQ(p.p_TA_B[kRR], Eigen::Vector3d(-p.c, -p.b_p, -p.wheel[kRR].z_offset));
}

TEST(Params, EmptyMessageReportsEveryMissingField) {
  const auto issues = ValidateVehicleParams(pb::VehicleParams());
  EXPECT_TRUE(HasIssue(issues, "mass", "missing"));
  EXPECT_TRUE(HasIssue(issues, "rr.radius", "missing"));
  EXPECT_TRUE(HasIssue(issues, "yaw_mode", "missing"));
  EXPECT_TRUE(HasIssue(issues, "model", "missing"));
  EXPECT_TRUE(HasIssue(issues, "engine_power_max", "missing"));
  EXPECT_TRUE(HasIssue(issues, "lf.spin_inertia", "missing"));
}

TEST(Params, OutOfRangeAndNonFiniteValuesNameFieldAndReason) {
  pb::VehicleParams m = DefaultVehicleParams();
  m.set_mass(-5.0);
  m.mutable_lf()->set_free_length(std::numeric_limits<double>::quiet_NaN());
  m.set_drive_front_fraction(1.5);
  m.mutable_rr()->set_bump_stop_length(0.5);  // longer than the 0.35 m free length
  m.set_izz(10000.0);                        // > ixx + iyy
  const auto issues = ValidateVehicleParams(m);
  EXPECT_TRUE(HasIssue(issues, "mass", "must be in (0, 100000], got -5")) << FormatIssues(issues);
  EXPECT_TRUE(HasIssue(issues, "lf.free_length", "finite number"));
  EXPECT_TRUE(HasIssue(issues, "drive_front_fraction", "got 1.5"));
  EXPECT_TRUE(HasIssue(issues, "rr.bump_stop_length", "shorter than free_length"));
  EXPECT_TRUE(HasIssue(issues, "izz", "no rigid body"));
  EXPECT_THROW(ParamsFromProto(m), ParamsError);
}

TEST(Params, UnknownEnumValuesAreRefused) {
  pb::VehicleParams m = DefaultVehicleParams();
  m.set_yaw_mode(static_cast<pb::YawMode>(7));
  m.set_tire_law(static_cast<pb::TireLaw>(9));
  m.set_model(static_cast<pb::VehicleModel>(5));
  const auto issues = ValidateVehicleParams(m);
  EXPECT_TRUE(HasIssue(issues, "yaw_mode", "7 is not one of YAW_MODE_DYNAMIC or YAW_MODE_PAPER"))
      << FormatIssues(issues);
  EXPECT_TRUE(HasIssue(issues, "tire_law", "9 is not one of"));
  EXPECT_TRUE(HasIssue(issues, "model", "5 is not one of"));
}

TEST(Params, FullModelRulesNameFieldAndReason) {
  pb::VehicleParams m = DefaultVehicleParams();
  m.set_shift_down_rpm(5500.0);               // an upshift at 6000 would land below it
  m.mutable_lr()->set_max_length(0.4);        // beyond the 0.35 m free length
  m.mutable_rf()->set_min_length(0.34);       // beyond max_length 0.33
  m.set_gear_count(11);
  m.set_mu_slide_ratio(0.0);
  m.set_differential(static_cast<pb::Differential>(7));
  m.mutable_lf()->set_damper_coefficient(0.0);  // the full model's wheel travel needs a damper
  const auto issues = ValidateVehicleParams(m);
  EXPECT_TRUE(HasIssue(issues, "shift_down_rpm", "hunt")) << FormatIssues(issues);
  EXPECT_TRUE(HasIssue(issues, "lr.max_length", "free_length"));
  EXPECT_TRUE(HasIssue(issues, "rf.min_length", "shorter than max_length"));
  EXPECT_TRUE(HasIssue(issues, "gear_count", "must be in [1, 10], got 11"));
  EXPECT_TRUE(HasIssue(issues, "mu_slide_ratio", "got 0"));
  EXPECT_TRUE(HasIssue(issues, "differential", "7 is not one of"));
  EXPECT_TRUE(HasIssue(issues, "lf.damper_coefficient", "full model"));
  // The paper's model has no such wheel travel: an undamped spring is its own business.
  pb::VehicleParams paper = DefaultVehicleParams();
  paper.set_model(pb::VEHICLE_MODEL_PAPER);
  paper.mutable_lf()->set_damper_coefficient(0.0);
  EXPECT_TRUE(ValidateVehicleParams(paper).empty()) << FormatIssues(ValidateVehicleParams(paper));
}

// A count too large for an int is refused with the number the file holds, not a clamped one
// (issue 20: "gear_count: 4000000000" was refused as "got 1000").
TEST(Params, AHugeGearCountIsRefusedWithTheNumberGiven) {
  for (const std::uint32_t n : {4'000'000'000u, 4'294'967'295u, 2'147'483'648u, 1001u, 0u}) {
    pb::VehicleParams m = DefaultVehicleParams();
    m.set_gear_count(n);
    const auto issues = ValidateVehicleParams(m);
    EXPECT_TRUE(HasIssue(issues, "gear_count", "must be in [1, 10], got " + std::to_string(n)))
        << FormatIssues(issues);
    EXPECT_THROW(ParamsFromProto(m), ParamsError);
  }
  TempDir dir;
  WriteFile(dir / "car.txt", "gear_count: 4000000000\n");
  try {
    LoadVehicleParamsFile(dir / "car.txt");
    ADD_FAILURE() << "gear_count 4000000000 was accepted";
  } catch (const ParamsError& e) {
    EXPECT_THAT(e.what(), HasSubstr("gear_count: number of forward gears must be in [1, 10], got "
                                    "4000000000"));
  }
}

TEST(Params, TextFileOverridesOnlyTheFieldsItLists) {
  TempDir dir;
  WriteFile(dir / "car.txt", "# a heavier car\nmass: 1800\nlf { spring_stiffness: 40000 }\n");
  const pb::VehicleParams m = LoadVehicleParamsFile(dir / "car.txt");
  EXPECT_EQ(m.mass(), 1800.0);
  EXPECT_EQ(m.lf().spring_stiffness(), 40000.0);
  const pb::VehicleParams d = DefaultVehicleParams();
  EXPECT_EQ(m.lf().damper_coefficient(), d.lf().damper_coefficient());
  EXPECT_EQ(m.rf().spring_stiffness(), d.rf().spring_stiffness());
  EXPECT_EQ(m.izz(), d.izz());
}

TEST(Params, JsonFileIsRead) {
  TempDir dir;
  WriteFile(dir / "car.json", R"({"mass": 1200, "yawMode": "YAW_MODE_PAPER", "rr": {"radius": 0.3}})");
  const pb::VehicleParams m = LoadVehicleParamsFile(dir / "car.json");
  EXPECT_EQ(m.mass(), 1200.0);
  EXPECT_EQ(m.yaw_mode(), pb::YAW_MODE_PAPER);
  EXPECT_EQ(m.rr().radius(), 0.3);
}

TEST(Params, SyntaxErrorNamesFileLineAndColumn) {
  TempDir dir;
  WriteFile(dir / "bad.txt", "mass: 1500\nixx: 500\nizz: banana\n");
  try {
    LoadVehicleParamsFile(dir / "bad.txt");
    FAIL() << "expected ParamsError";
  } catch (const ParamsError& e) {
    EXPECT_THAT(e.what(), HasSubstr("bad.txt"));
    EXPECT_THAT(e.what(), HasSubstr("line 3"));
  }
}

TEST(Params, UnknownFieldIsRejected) {
  try {
    ParseVehicleParams("mass: 1500\nwings: 2\n", false, "car.txt");
    FAIL() << "expected ParamsError";
  } catch (const ParamsError& e) {
    EXPECT_THAT(e.what(), HasSubstr("car.txt"));
    EXPECT_THAT(e.what(), HasSubstr("wings"));
  }
  EXPECT_THROW(ParseVehicleParams(R"({"wings": 2})", true, "car.json"), ParamsError);
}

TEST(Params, InvalidValueInFileNamesFieldAndReason) {
  try {
    ParseVehicleParams("rf { radius: -0.3 }\n", false, "car.txt");
    FAIL() << "expected ParamsError";
  } catch (const ParamsError& e) {
    EXPECT_THAT(e.what(), HasSubstr("car.txt: rf.radius: wheel radius, m must be in (0, 3]"));
  }
}

TEST(Params, MissingFileIsAClearError) {
  try {
    LoadVehicleParamsFile("/nonexistent/car.txt");
    FAIL() << "expected ParamsError";
  } catch (const ParamsError& e) {
    EXPECT_THAT(e.what(), HasSubstr("/nonexistent/car.txt: no such vehicle parameter file"));
  }
  // A file that never ends is refused at the bound while it is read (it filled the memory).
  try {
    LoadVehicleParamsFile("/dev/zero");
    FAIL() << "expected ParamsError";
  } catch (const ParamsError& e) {
    EXPECT_THAT(e.what(), HasSubstr("/dev/zero: more than 4194304 bytes, more than a vehicle "
                                    "parameter file may have"));
  }
}

TEST(Params, DumpReadsBackToTheSameMessage) {
  pb::VehicleParams m = DefaultVehicleParams();
  m.set_mass(1234.5678901234567);
  m.mutable_lr()->set_cornering_stiffness(7.0e4 / 3.0);
  const std::string text = DumpVehicleParamsText(m);
  const pb::VehicleParams back = ParseVehicleParams(text, false, "dump");
  EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(m, back)) << text;
}

}  // namespace
}  // namespace vdyn
