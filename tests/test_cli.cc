// vdyn-server as a user runs it: exit codes and messages for good and bad input.
#include <sys/wait.h>

#include <array>
#include <cstdio>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "vdyn/io/csv.h"
#include "vdyn/bridge/params.h"
#include "process.h"
#include <filesystem>
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

// Every numeric option of vdyn-server is checked for a finite number in its range, in one place
// (vdyn/cli/options.h with the table of limits): NaN, infinities, absurd magnitudes and text are
// usage errors (exit code 2) naming the option, never a run with a broken number.
struct BadOption {
  const char* args;
  const char* message;
};
class ServerRefusesBadNumbers : public ::testing::TestWithParam<BadOption> {};

TEST_P(ServerRefusesBadNumbers, WithExitCode2AndTheOptionNamed) {
  testing::UseLoopbackDds();
  const Result r =
      RunServer(std::string(GetParam().args) + " --domain " + std::to_string(testing::FreshDomain()));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_THAT(r.output, HasSubstr(GetParam().message));
  EXPECT_EQ(r.output.find("e+"), std::string::npos) << "limits are printed as a person writes them";
}

INSTANTIATE_TEST_SUITE_P(
    Options, ServerRefusesBadNumbers,
    ::testing::Values(
        BadOption{"--step-ms nan", "--step-ms: 'nan' is not a finite number"},
        BadOption{"--step-ms 1e300",
                  "--step-ms: integration step, ms must be in [0.01, 100], got 1e300"},
        BadOption{"--lockstep --lockstep-timeout nan",
                  "--lockstep-timeout: 'nan' is not a finite number"},
        BadOption{"--watchdog-ms nan", "--watchdog-ms: 'nan' is not a finite number"},
        BadOption{"--watchdog-ms -5", "watchdog, ms must be in [1, 60000], got -5"},
        BadOption{"--batch --maneuver demo --duration nan",
                  "--duration: 'nan' is not a finite number"},
        BadOption{"--batch --maneuver demo --duration 1e300",
                  "duration, s must be in (0, 1e7], got 1e300"},
        BadOption{"--duration inf", "--duration: 'inf' is not a finite number"},
        BadOption{"--batch --maneuver demo --speed-kmh nan",
                  "--speed-kmh: 'nan' is not a finite number"},
        BadOption{"--batch --maneuver demo --spawn nan,0,0",
                  "--spawn: 'nan' is not a finite number"},
        BadOption{"--batch --maneuver demo --csv-every 0", "must be in [1, 1000000], got 0"},
        BadOption{"--domain 1.5", "--domain: '1.5' is not a whole number"},
        BadOption{"--domain 999", "DDS domain id must be in [0, 232], got 999"},
        BadOption{"--max-vehicles 0",
                  "--max-vehicles: vehicles per server must be in [1, 256], got 0"},
        BadOption{"--max-vehicles 257",
                  "--max-vehicles: vehicles per server must be in [1, 256], got 257"},
        BadOption{"--max-vehicles abc", "--max-vehicles: 'abc' is not a number"},
        BadOption{"--max-vehicles 2.5", "--max-vehicles: '2.5' is not a whole number"},
        BadOption{"--rt-priority abc", "--rt-priority: 'abc' is not a number"},
        BadOption{"--world-scale inf", "--world-scale: 'inf' is not a finite number"},
        BadOption{"--heightmap-cell 0", "height-map cell, m must be in (0, 10000], got 0"}));

// A number too small for a double is a number: it underflows to zero, as on paper.
TEST(Cli, ANumberThatUnderflowsIsZero) {
  TempDir dir;
  WriteFile(dir / "m.csv", "t_s,steer_deg,throttle,brake\n0,1e-400,0,0\n1,0,0,0\n");
  const Result r = RunServer("--batch --world flat --maneuver " + (dir / "m.csv").string() +
                             " --speed-kmh 1e-400 --duration 0.5");
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

// Files that are not what they claim: a directory, a truncated binary height map, a mesh with one
// NaN vertex (its triangle is dropped and counted; the rest is the world), a CSV with a BOM.
TEST(Cli, DirectoriesAndBrokenFilesAreRefusedOrRepairedWithTheReason) {
  TempDir dir;
  const Result vehicle_dir = RunServer("--dump-vehicle --vehicle " + dir.path().string());
  EXPECT_EQ(vehicle_dir.exit_code, 2);
  EXPECT_THAT(vehicle_dir.output, HasSubstr("is a directory, not a vehicle parameter file"));
  const Result maneuver_dir = RunServer("--batch --maneuver " + dir.path().string());
  EXPECT_EQ(maneuver_dir.exit_code, 2);
  EXPECT_THAT(maneuver_dir.output, HasSubstr("is a directory, not a maneuver file"));

  std::string pgm = "P5\n64 64\n255\n";
  pgm += std::string(100, '\x40');
  WriteFile(dir / "short.pgm", pgm);
  const Result short_pgm = RunServer("--batch --maneuver demo --world " + (dir / "short.pgm").string());
  EXPECT_EQ(short_pgm.exit_code, 2);
  EXPECT_THAT(short_pgm.output,
              HasSubstr("short.pgm: the image data is cut short: 64 x 64 pixels need 4096 bytes "
                        "of pixels, the file holds 100"));

  WriteFile(dir / "nan.obj",
            "v -50 -50 0\nv 50 -50 0\nv 50 50 0\nv -50 50 0\nv nan 0 1\nv 1 1 1\n"
            "f 1 2 3\nf 1 3 4\nf 5 6 1\n");
  const Result nan_obj = RunServer("--batch --maneuver demo --duration 1 --spawn 0,0,0 --world " +
                                   (dir / "nan.obj").string());
  EXPECT_EQ(nan_obj.exit_code, 0) << nan_obj.output;
  EXPECT_THAT(nan_obj.output, HasSubstr("1 of 3 triangles dropped"));

  WriteFile(dir / "bom.csv", "\xEF\xBB\xBFt_s,steer_deg,throttle,brake\n0,0,0.5,0\n1,0,0.5,0\n");
  const Result bom = RunServer("--batch --world flat --maneuver " + (dir / "bom.csv").string());
  EXPECT_EQ(bom.exit_code, 0) << bom.output;
}

// A spawn inside a wall is refused with the reason, not run at 2,338,476 km/h.
TEST(Cli, ASpawnInsideAWallIsRefused) {
  const Result r =
      RunServer("--batch --world facility --spawn 290.15,0,0 --maneuver demo --duration 1");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_THAT(r.output, HasSubstr("the body would start inside 'glass_barrier'"));
}

// A binary that reads no options still answers a bad command line with exit code 2.
TEST(Cli, ServerThatCannotStartItsVehiclesSaysWhy) {
  testing::UseLoopbackDds();
  const std::string domain = " --domain " + std::to_string(testing::FreshDomain());
  const Result twice = RunServer("--vehicle-ids 1,1 --duration 1" + domain);
  EXPECT_EQ(twice.exit_code, 2) << twice.output;
  EXPECT_THAT(twice.output, HasSubstr("vehicle 1 exists already"));
  const Result over = RunServer("--max-vehicles 2 --vehicle-ids 1,2,3 --duration 1" + domain);
  EXPECT_EQ(over.exit_code, 2) << over.output;
  EXPECT_THAT(over.output, HasSubstr("this server runs its maximum of 2 vehicles"));
  const Result nowhere = RunServer("--world facility --spawn 5000,5000,0 --duration 1" + domain);
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

TEST(CliInput, PlayIsTheManeuverPlaybackAndASubcommandIsNeeded) {
  Result r = RunInput("play /nonexistent/m.csv");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.output, HasSubstr("/nonexistent/m.csv: no such maneuver file"));
  r = RunInput("");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.output, HasSubstr("choose what drives: drive, keyboard, list, calibrate, or play"));
}

TEST(CliInput, RigOptionsAreCheckedAgainstTheLimits) {
  Result r = RunInput("drive --ffb-cap-nm 60");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.output, HasSubstr("hand-wheel torque, N*m must be in [0, 50], got 60"));
  r = RunInput("drive --ffb-gain nan");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.output, HasSubstr("'nan' is not a finite number"));
  r = RunInput("calibrate --range-deg 10");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.output, HasSubstr("wheel rotation range, degree must be in [90, 3600], got 10"));
}

TEST(CliInput, WithoutDevicesListSaysSoAndCalibrateRefuses) {
  // The test machine has no joystick devices (and SDL's virtual ones live only in a process).
  Result r = RunInput("list --once");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("no joystick devices"));
  r = RunInput("calibrate --timeout 5");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.output, HasSubstr("no device to calibrate"));
}

TEST(CliInput, DriveWithoutAServerEndsWithAMessage) {
  testing::UseLoopbackDds();
  const Result r = RunInput("--domain 229 --wait 1 drive");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.output, HasSubstr("no parameters of vehicle 1 on domain 229 within 1 s"));
}

TEST(CliInput, NoServerEndsWithAMessageNotAHang) {
  testing::UseLoopbackDds();
  const std::uint32_t domain = testing::FreshDomain();
  const Result r = RunInput("--maneuver demo --wait 1 --domain " + std::to_string(domain));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.output, HasSubstr("no state of vehicle 1 on domain " + std::to_string(domain) +
                                  " within 1 s"));
}

}  // namespace
}  // namespace vdyn
