// vdyn-server as a user runs it: exit codes and messages for good and bad input.
#include <sys/wait.h>

#include <array>
#include <cstdio>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "vdyn/io/csv.h"
#include "vdyn/bridge/params.h"
#include "process.h"
#include "test_support.h"

namespace vdyn {
namespace {

using ::testing::HasSubstr;
using testing::TempDir;
using testing::WriteFile;

struct Result {
  int exit_code;
  std::string output;  // stdout and stderr
};

Result Run(const std::string& binary, const std::string& args) {
  // Bounded: a process that does not stop on its own is killed after 120 s.
  const std::string cmd = "timeout -s KILL 120 " + binary + " " + args + " 2>&1";
  Result r{-1, {}};
  FILE* pipe = popen(cmd.c_str(), "r");
  if (pipe == nullptr) return r;
  std::array<char, 4096> buf;
  while (std::fgets(buf.data(), buf.size(), pipe) != nullptr) r.output += buf.data();
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

Result RunServer(const std::string& args) { return Run(VDYN_SERVER_BINARY, args); }
Result RunInput(const std::string& args) { return Run(VDYN_INPUT_BINARY, args); }

TEST(Cli, DumpVehicleReadsBackThroughVehicle) {
  TempDir dir;
  const Result dump = RunServer("--dump-vehicle");
  ASSERT_EQ(dump.exit_code, 0) << dump.output;
  WriteFile(dir / "car.txt", dump.output);
  const pb::VehicleParams parsed = LoadVehicleParamsFile(dir / "car.txt");
  EXPECT_EQ(parsed.SerializeAsString(), DefaultVehicleParams().SerializeAsString());
  const Result again = RunServer("--dump-vehicle --vehicle " + (dir / "car.txt").string());
  EXPECT_EQ(again.output, dump.output);
}

TEST(Cli, ModelOptionChoosesTheModelAndRefusesOthers) {
  const Result paper = RunServer("--model paper --dump-vehicle");
  ASSERT_EQ(paper.exit_code, 0) << paper.output;
  EXPECT_THAT(paper.output, HasSubstr("model: VEHICLE_MODEL_PAPER"));
  const Result full = RunServer("--dump-vehicle");
  EXPECT_THAT(full.output, HasSubstr("model: VEHICLE_MODEL_FULL"));  // the default
  const Result bad = RunServer("--model bicycle --dump-vehicle");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_THAT(bad.output, HasSubstr("--model"));
  // The paper's model's demo drive ends on its golden hash (tests/test_golden.cc).
  TempDir dir;
  const Result demo = RunServer("--demo --model paper --csv " + (dir / "d.csv").string());
  ASSERT_EQ(demo.exit_code, 0) << demo.output;
  EXPECT_THAT(demo.output, HasSubstr("state hash f00662dacbdc2b22"));
}

TEST(Cli, BatchWritesTheCsvWithUnitsInTheHeader) {
  TempDir dir;
  WriteFile(dir / "m.csv", "t_s,steer_deg,throttle,brake,cruise_kmh\n0,0,0,0,30\n2,3,0,0,30\n");
  const Result r = RunServer("--batch --world flat --maneuver " + (dir / "m.csv").string() +
                       " --duration 2 --csv " + (dir / "out.csv").string() + " --csv-every 10");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("2.000 s simulated"));
  const std::string csv = testing::ReadFile(dir / "out.csv");
  const std::string header = csv.substr(0, csv.find('\n'));
  for (const char* col : {"t_s", "x_m", "y_m", "z_m", "roll_rad", "pitch_rad", "yaw_rad", "vx_mps",
                          "wz_radps", "ax_mps2", "az_mps2", "Da_N", "Fp_LF_N", "Fh_RF_N",
                          "Fb_LR_N", "Fy_RR_N", "lS_LF_m", "contact_RR", "gamma_LF_rad",
                          "Tsteer_align_Nm", "engine_rpm", "gear", "omega_LF_radps", "Mz_RF_Nm",
                          "kappa_RR"}) {
    EXPECT_THAT(header, HasSubstr(col));
  }
  EXPECT_EQ(header.find(' '), std::string::npos);
  // 2000 steps every 10th, plus the final state.
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 1 + 200 + 1);
}

TEST(Cli, MalformedManeuverIsRefusedWithLineAndReason) {
  TempDir dir;
  WriteFile(dir / "m.csv", "t_s,steer_deg,throttle,brake\n0,0,0,0\n1,0,0,2\n");
  const Result r = RunServer("--batch --world flat --maneuver " + (dir / "m.csv").string());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.output, HasSubstr("m.csv:3: column 'brake': 2 is outside [0, 1]"));
}

TEST(Cli, InvalidVehicleFileIsRefusedWithFieldAndReason) {
  TempDir dir;
  WriteFile(dir / "car.txt", "mass: 0\n");
  WriteFile(dir / "m.csv", "t_s,steer_deg,throttle,brake\n0,0,0,0\n");
  const Result r = RunServer("--batch --world flat --maneuver " + (dir / "m.csv").string() +
                       " --vehicle " + (dir / "car.txt").string());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.output, HasSubstr("car.txt: mass: vehicle mass, kg must be in (0, 100000], got 0"));
}

TEST(Cli, MissingWorldFileIsRefused) {
  const Result r = RunServer("--batch --world /nonexistent/hills.obj --maneuver demo");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.output, HasSubstr("/nonexistent/hills.obj: no such file"));
}

TEST(Cli, UnknownOptionIsAUsageError) {
  const Result r = RunServer("--warp-speed 9");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.output, HasSubstr("--warp-speed"));
}

TEST(Cli, BadOptionValueIsRefused) {
  const Result r = RunServer("--batch --maneuver demo --step-ms 0");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.output, HasSubstr("--step-ms"));
}

TEST(Cli, ServerThatCannotStartItsVehiclesSaysWhy) {
  const Result twice = RunServer("--vehicle-ids 1,1 --domain 231 --duration 1");
  EXPECT_EQ(twice.exit_code, 2) << twice.output;
  EXPECT_THAT(twice.output, HasSubstr("vehicle 1 exists already"));
  const Result nowhere = RunServer("--world facility --spawn 5000,5000,0 --domain 231 --duration 1");
  EXPECT_EQ(nowhere.exit_code, 2) << nowhere.output;
  EXPECT_THAT(nowhere.output, HasSubstr("no terrain below wheel"));
}

TEST(Cli, DemoRunsAndSaysWhereTheCsvIs) {
  TempDir dir;
  const Result r = RunServer("--demo --csv " + (dir / "demo.csv").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("demo drive on facility"));
  EXPECT_THAT(r.output, HasSubstr("CSV: " + (dir / "demo.csv").string()));
  EXPECT_TRUE(std::filesystem::file_size(dir / "demo.csv") > 0);
}

}  // namespace
}  // namespace vdyn

namespace vdyn {
namespace {

TEST(CliInput, BadManeuverIsRefusedWithTheReason) {
  const Result r = RunInput("--maneuver /nonexistent/m.csv");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.output, HasSubstr("/nonexistent/m.csv: no such maneuver file"));
}

TEST(CliInput, NoServerEndsWithAMessageNotAHang) {
  testing::UseLoopbackDds();
  const Result r = RunInput("--maneuver demo --domain 230 --wait 1");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.output, HasSubstr("no state of vehicle 1 on domain 230 within 1 s"));
}

}  // namespace
}  // namespace vdyn
