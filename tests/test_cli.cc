// The programs as a user runs them: vdyn-server's and vdyn-input's exit codes and messages for good
// and bad input, and every program's wrong command line told the same way (base/cli).
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <sstream>
#include <thread>
#include <tuple>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "vdyn/base/deadline.h"
#include "vdyn/cli/errors.h"
#include "vdyn/cli/options.h"
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
  EXPECT_THAT(demo.output, HasSubstr("state hash 65de67228a69d83c"));
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
        BadOption{"--step-threads 0", "--step-threads: stepping threads must be in [1, 16], got 0"},
        BadOption{"--step-threads 17",
                  "--step-threads: stepping threads must be in [1, 16], got 17"},
        BadOption{"--step-threads 1.5", "--step-threads: '1.5' is not a whole number"},
        BadOption{"--step-threads two", "--step-threads: 'two' is not a number"},
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

// vdyn-server run with `args` exits with `code` and says `text`.
void ExpectServerSays(const std::string& args, int code, const std::string& text) {
  const Result r = RunServer(args);
  EXPECT_EQ(r.exit_code, code) << args << "\n" << r.output;
  EXPECT_THAT(r.output, HasSubstr(text)) << args;
}

// A binary that reads no options still answers a bad command line with exit code 2.
TEST(Cli, ServerThatCannotStartItsVehiclesSaysWhy) {
  testing::UseLoopbackDds();
  const std::string domain = " --domain " + std::to_string(testing::FreshDomain());
  ExpectServerSays("--vehicle-ids 1,1 --duration 1" + domain, 2,
                   "vdyn-server: --vehicle-ids: vehicle 1 is listed twice");
  ExpectServerSays("--max-vehicles 2 --vehicle-ids 1,2,3 --duration 1" + domain, 2,
                   "vdyn-server: --vehicle-ids lists 3 vehicles and --max-vehicles is 2: raise "
                   "--max-vehicles to 3 (at most 256) or list fewer");
  ExpectServerSays("--vehicle-ids 1..65 --duration 1" + domain, 2,
                   "--vehicle-ids lists 65 vehicles and --max-vehicles is 64");
  ExpectServerSays("--world facility --spawn 5000,5000,0 --duration 1" + domain, 2,
                   "no terrain below wheel");
}

// An option of another mode than the one run is refused with the reason, never ignored (a
// networked server took --csv and wrote nothing, --lockstep ran past --duration, --batch with
// --lockstep ran the batch).
TEST(Cli, ServerRefusesOptionsOfAnotherMode) {
  testing::UseLoopbackDds();
  const std::string domain = " --domain " + std::to_string(testing::FreshDomain());
  ExpectServerSays("--world flat --duration 1 --csv rt.csv" + domain, 2,
                   "vdyn-server: --csv is for --batch (or --demo)");
  ExpectServerSays("--world flat --duration 1 --maneuver demo" + domain, 2,
                   "--maneuver is for --batch");
  ExpectServerSays("--lockstep --duration 0.5" + domain, 2,
                   "--duration is for real time and --batch: a lockstep server steps as its "
                   "client asks");
  ExpectServerSays("--batch --lockstep --maneuver demo", 2,
                   "--batch and --lockstep are two things to do: give one");
  ExpectServerSays("--dump-maneuver demo --dump-vehicle", 2,
                   "--dump-vehicle and --dump-maneuver are two things to do");
  ExpectServerSays("--demo --csv out.csv" + domain, 2,
                   "--domain is for a networked server; --demo runs without one");
  ExpectServerSays("--dump-vehicle --fz 3000", 2, "--fz is for --tire-curves");
  ExpectServerSays("--world flat --duration 1 --lockstep-timeout 5" + domain, 2,
                   "--lockstep-timeout is for --lockstep");
  // Its end said in the figure given ("0.30000000000000004 s" before).
  ExpectServerSays("--lockstep --lockstep-timeout 0.3" + domain, 3,
                   "lockstep: no control request for 0.3 s;");
}

// Without --step-threads the server steps up to 128 --max-vehicles on its loop thread alone (a
// second thread costs more than it saves on a shared machine: bench/README.md), and one more
// thread per 128 above, where the machine has the cores. Its log line says what it chose.
TEST(Cli, ServerChoosesOneSteppingThreadPer128Vehicles) {
  testing::UseLoopbackDds();
  const std::string domain = " --domain " + std::to_string(testing::FreshDomain());
  ExpectServerSays("--max-vehicles 128 --duration 0.05 --no-status" + domain, 0,
                   "; 1 stepping thread(s);");
  if (std::thread::hardware_concurrency() >= 2) {
    ExpectServerSays("--max-vehicles 129 --duration 0.05 --no-status" + domain, 0,
                     "; 2 stepping thread(s);");
  }
  ExpectServerSays("--step-threads 3 --duration 0.05 --no-status" + domain, 0,
                   "; 3 stepping thread(s);");
}

// A server id goes into every message the server sends: empty, longer than an id may be (64
// bytes, which every reader would refuse), or with control characters, it is refused.
TEST(Cli, AServerIdThatCannotBeAnIdIsRefused) {
  const Result empty = RunServer("--server-id '' --duration 1");
  EXPECT_EQ(empty.exit_code, 2) << empty.output;
  EXPECT_THAT(empty.output, HasSubstr("--server-id: the server id is empty"));
  const Result blank = RunServer("--server-id ' ' --duration 1");
  EXPECT_EQ(blank.exit_code, 2) << blank.output;
  EXPECT_THAT(blank.output, HasSubstr("--server-id: the server id is empty"));
  const Result longer = RunServer("--server-id " + std::string(65, 'x') + " --duration 1");
  EXPECT_EQ(longer.exit_code, 2) << longer.output;
  EXPECT_THAT(longer.output, HasSubstr("the server id is 65 bytes long; at most 64"));
  const Result control = RunServer("--server-id \"$(printf 'lab\\ta')\" --duration 1");
  EXPECT_EQ(control.exit_code, 2) << control.output;
  EXPECT_THAT(control.output, HasSubstr("the server id holds a control character"));
}

TEST(Cli, DemoRunsAndSaysWhereTheCsvIs) {
  TempDir dir;
  const Result r = RunServer("--demo --csv " + (dir / "demo.csv").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("demo drive on facility"));
  EXPECT_THAT(r.output, HasSubstr("CSV: " + (dir / "demo.csv").string()));
  EXPECT_TRUE(std::filesystem::file_size(dir / "demo.csv") > 0);
}

// The CSV is written on a second thread; a device that takes no data still ends the run with the
// reason and a failing exit code, not a crash or a silent short file.
TEST(Cli, ACsvThatCannotBeWrittenEndsTheRunWithTheReason) {
  if (!std::filesystem::exists("/dev/full")) GTEST_SKIP() << "no /dev/full here";
  const Result r = RunServer("--batch --world flat --maneuver demo --duration 2 --csv /dev/full");
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("/dev/full: writing the CSV failed"));
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
  const std::string domain = std::to_string(testing::FreshDomain());
  const Result r = RunInput("--domain " + domain + " --wait 1 drive");
  EXPECT_EQ(r.exit_code, 1);
  // The wait said as it starts (nothing was said for the whole --wait), then its end.
  EXPECT_THAT(r.output,
              HasSubstr("vdyn-input: waiting up to 1 s for vehicle 1 on domain " + domain));
  EXPECT_THAT(r.output, HasSubstr("no parameters of vehicle 1 on domain " + domain + " within 1 s"));
}

// Ctrl-C during drive's --wait ends it (it waited out the whole --wait: an hour for --wait 3600).
TEST(CliInput, CtrlCEndsTheWaitForAServer) {
  testing::UseLoopbackDds();
  TempDir dir;
  const std::string domain = std::to_string(testing::FreshDomain());
  testing::Process input({testing::InputBinary(), "--domain", domain, "--wait", "3600", "drive",
                          "--no-window"},
                         dir / "input.log");
  const bool waiting = base::PollUntil(
      base::Deadline::After(base::Seconds(60)), base::Milliseconds(50),
      [&] { return input.Log().find("waiting up to 3600 s") != std::string::npos; },
      [](base::Nanos slice) { std::this_thread::sleep_for(base::Chrono(slice)); });
  ASSERT_TRUE(waiting) << input.Log();
  input.Signal(SIGINT);
  EXPECT_EQ(input.Wait(std::chrono::seconds(30)), 0) << input.Log();
  EXPECT_THAT(input.Log(), HasSubstr("vdyn-input: stopped while waiting for vehicle 1"));
}

// A server runs, but not with the vehicle asked for: play and drive name the vehicles there are
// and how to drive one, not "is vdyn-server running?".
TEST(CliInput, AVehicleTheServerDoesNotHaveIsToldWithTheVehiclesThereAre) {
  testing::UseLoopbackDds();
  TempDir dir;
  WriteFile(dir / "m.csv", "t_s,steer_deg,throttle,brake,cruise_kmh\n0,0,0.2,0,0\n0.3,0,0.2,0,0\n");
  const std::string domain = std::to_string(testing::FreshDomain());
  const std::string maneuver = (dir / "m.csv").string();
  testing::Process server({testing::ServerBinary(), "--domain", domain, "--vehicle-ids", "1,3",
                           "--duration", "120", "--no-status"},
                          dir / "server.log");
  // The server is up once vehicle 1 takes a maneuver.
  const Result up = RunInput("--domain " + domain + " --wait 60 play " + maneuver);
  ASSERT_EQ(up.exit_code, 0) << up.output << server.Log();
  const std::string why =
      "; vdyn-server there has vehicles 1,3: drive one with --vehicle-id 1, or "
      "start vdyn-server with --vehicle-ids 1,3,2";
  Result r = RunInput("--domain " + domain + " --vehicle-id 2 --wait 1 play " + maneuver);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output,
              HasSubstr("no state of vehicle 2 on domain " + domain + " within 1 s" + why));
  r = RunInput("--domain " + domain + " --vehicle-id 2 play " + maneuver + " --clock wall");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("but no server took it: no state of vehicle 2 on domain " +
                                  domain + " arrived" + why));
  r = RunInput("--domain " + domain + " --vehicle-id 2 --wait 1 drive --no-window");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output,
              HasSubstr("no parameters of vehicle 2 on domain " + domain + " within 1 s" + why));
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

// --- Every program's wrong command line, told the same way (base/cli: vdyn/cli/errors.h) ------

namespace vdyn {
namespace {

using ::testing::ElementsAre;
using ::testing::Not;

Result RunRecorder(const std::string& args) {
  return Run(testing::RecorderBinary(), args);
}
Result RunTelemetry(const std::string& args) {
  return Run(VDYN_TELEMETRY_BINARY, args);
}
Result RunViewer(const std::string& args) {
  return Run(VDYN_VIEWER_BINARY, args);
}

// A command line a program refuses as a usage error: exit code 2, `message` in its output.
struct UsageCase {
  Result (*run)(const std::string&);
  std::string args;
  std::string message;
};
// Runs each case; `never`: words no refusal may hold (CLI11's own wording, say).
void ExpectUsageErrors(const std::vector<UsageCase>& cases,
                       const std::vector<std::string>& never = {}) {
  for (const UsageCase& c : cases) {
    const Result r = c.run(c.args);
    EXPECT_EQ(r.exit_code, 2) << c.args << "\n" << r.output;
    EXPECT_THAT(r.output, HasSubstr(c.message)) << c.args;
    for (const std::string& n : never) EXPECT_THAT(r.output, Not(HasSubstr(n))) << c.args;
  }
}

TEST(CliErrors, EditDistanceCountsASwapOfNeighboursAsOne) {
  EXPECT_EQ(cli::EditDistance("kitten", "sitting"), 3);  // Levenshtein's example
  EXPECT_EQ(cli::EditDistance("wrold", "world"), 1);     // a swap
  EXPECT_EQ(cli::EditDistance("recrod", "record"), 1);
  EXPECT_EQ(cli::EditDistance("", "abc"), 3);
  EXPECT_EQ(cli::EditDistance("World", "world"), 0);
  EXPECT_EQ(cli::EditDistance("ca", "abc"), 3);  // optimal string alignment: no edit of a swap
}

TEST(CliErrors, NearestNamesTheClosestOnlyAndNothingFar) {
  const std::vector<std::string> options{
      "--world", "--world-scale",      "--vehicle", "--vehicle-ids", "--help",
      "-h",      "--lockstep-timeout", "--lockstep"};
  EXPECT_THAT(cli::Nearest("--wrold", options), ElementsAre("--world"));
  EXPECT_THAT(cli::Nearest("--vehicle-id", options), ElementsAre("--vehicle-ids"));
  EXPECT_THAT(cli::Nearest("--lockstep-time", options), ElementsAre("--lockstep-timeout"));
  EXPECT_THAT(cli::Nearest("-world", options), ElementsAre("--world"));
  EXPECT_TRUE(cli::Nearest("--warp-speed", options).empty());
  EXPECT_TRUE(cli::Nearest("--x", options).empty());
  EXPECT_THAT(cli::Nearest("--h", options), ElementsAre("-h"));
  const std::vector<std::string> commands{"record", "info",   "export",   "plot",
                                          "play",   "verify", "takeover", "recover"};
  EXPECT_THAT(cli::Nearest("recrod", commands), ElementsAre("record"));
  EXPECT_THAT(cli::Nearest("paly", commands), ElementsAre("play"));
  EXPECT_TRUE(cli::Nearest("dance", commands).empty());
}

// An app shaped like the programs: options at the top, commands with their own options.
struct TestApp {
  CLI::App app{"test"};
  std::string world;
  std::vector<std::uint32_t> ids;
  std::string out, file;
  double rate = 1;
  std::uint32_t domain = 0;
  CLI::App* record = nullptr;
  CLI::App* play = nullptr;
  explicit TestApp(bool commands) {
    app.add_option("--world", world, "the world");
    app.add_option("--vehicle-ids", ids, "ids")->delimiter(',');
    if (!commands) return;
    app.require_subcommand(1);
    record = app.add_subcommand("record", "record");
    record->add_option("out", out, "the file")->required();
    record->add_option("--domain", domain, "domain");
    play = app.add_subcommand("play", "play");
    play->add_option("file", file, "the file")->required();
    play->add_option("--rate", rate, "rate");
    play->add_option("--domain", domain, "domain");
  }
  // Parses as the program "prog"; the exit code and what it wrote to the error stream.
  std::pair<int, std::string> Parse(std::vector<std::string> args) {
    args.insert(args.begin(), "/usr/bin/prog");
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    std::ostringstream err;
    const int code = cli::Parse(app, static_cast<int>(argv.size()), argv.data(), err);
    return {code, err.str()};
  }
};

TEST(CliErrors, AnUnknownOptionIsNamedWithTheNearestAndItsValueIsNotASecondProblem) {
  TestApp t(false);
  const auto [code, err] = t.Parse({"--wrold", "facility"});
  EXPECT_EQ(code, 2);
  EXPECT_EQ(err,
            "prog: unknown option '--wrold'; did you mean '--world'?\n"
            "Run 'prog --help' for more information.\n");
  TestApp t2(false);
  EXPECT_THAT(t2.Parse({"--wrold=facility"}).second,
              HasSubstr("prog: unknown option '--wrold'; did you mean '--world'?"));
  TestApp t3(false);
  EXPECT_THAT(t3.Parse({"--warp-speed", "9"}).second,
              HasSubstr("prog: unknown option '--warp-speed'\n"));
  TestApp t4(false);
  EXPECT_THAT(t4.Parse({"world", "facility"}).second,
              HasSubstr("prog: unexpected argument 'world'; did you mean '--world'?"));
  TestApp t5(false);
  EXPECT_THAT(t5.Parse({"--world", "flat", "hills.obj"}).second,
              HasSubstr("prog: unexpected argument 'hills.obj' (prog takes options only)"));
  TestApp ok(false);
  EXPECT_EQ(ok.Parse({"--world", "flat"}).first, -1);
  EXPECT_EQ(ok.world, "flat");
}

TEST(CliErrors, AnUnknownCommandIsNamedWithTheNearestAndTheCommands) {
  TestApp t(true);
  const auto [code, err] = t.Parse({"recrod", "x.mcap"});
  EXPECT_EQ(code, 2);
  EXPECT_EQ(err,
            "prog: unknown command 'recrod'; did you mean 'record'? (the commands: record, play)\n"
            "Run 'prog --help' for more information.\n");
  TestApp none(true);
  EXPECT_THAT(none.Parse({}).second, HasSubstr("prog: choose a command: record, play\n"));
}

TEST(CliErrors, AnOptionOfAnotherCommandSaysWhereItBelongs) {
  TestApp before(true);
  auto [code, err] = before.Parse({"--domain", "3", "record", "x.mcap"});
  EXPECT_EQ(code, 2);
  EXPECT_THAT(err, HasSubstr("prog record: option '--domain' goes after the command: "
                             "prog record ... --domain"));
  TestApp other(true);
  std::tie(code, err) = other.Parse({"record", "x.mcap", "--rate", "2"});
  EXPECT_EQ(code, 2);
  EXPECT_THAT(err, HasSubstr("prog record: option '--rate' is not one of 'prog record'; it "
                             "belongs to 'prog play'"));
  EXPECT_THAT(err, HasSubstr("Run 'prog record --help' for more information."));
  TestApp typo(true);
  std::tie(code, err) = typo.Parse({"play", "x.mcap", "--rtae", "2"});
  EXPECT_THAT(err, HasSubstr("prog play: unknown option '--rtae'; did you mean '--rate'?"));
  TestApp extra(true);
  std::tie(code, err) = extra.Parse({"play", "x.mcap", "y.mcap"});
  EXPECT_EQ(code, 2);
  EXPECT_THAT(err, HasSubstr("prog play: unexpected argument 'y.mcap' (prog play takes FILE and "
                             "options)"));
}

TEST(CliErrors, AListWithAnEmptyEntryIsRefusedNotShortened) {
  for (const auto& [args, message] : std::vector<std::pair<std::vector<std::string>, std::string>>{
           {{"--vehicle-ids", "1,,2"}, "--vehicle-ids '1,,2': entry 2 of the list is empty"},
           {{"--vehicle-ids=1,2,"}, "--vehicle-ids '1,2,': entry 3 of the list is empty"},
           {{"--vehicle-ids", ",1"}, "--vehicle-ids ',1': entry 1 of the list is empty"},
           {{"--vehicle-ids", ""}, "--vehicle-ids '': the list is empty"},
           {{"--vehicle-ids", "1,", "2"},
            "--vehicle-ids '1,': entry 2 of the list is empty (a space after a comma ends the "
            "list"}}) {
    TestApp t(false);
    const auto [code, err] = t.Parse(args);
    EXPECT_EQ(code, 2) << message;
    EXPECT_THAT(err, HasSubstr("prog: " + message));
  }
  TestApp ok(false);
  ASSERT_EQ(ok.Parse({"--vehicle-ids", "1,2,3"}).first, -1);
  EXPECT_THAT(ok.ids, ElementsAre(1u, 2u, 3u));
}

// CLI11's own wording of a value of the wrong type, a missing value or argument, as a person says
// it.
TEST(CliErrors, WrongValuesAndMissingArgumentsAreSaidPlainly) {
  TestApp conversion(false);
  EXPECT_THAT(conversion.Parse({"--vehicle-ids", "-1"}).second,
              HasSubstr("prog: --vehicle-ids: '-1' is not a whole number, 0 or more\n"));
  TestApp octal(false);
  ASSERT_EQ(octal.Parse({"--vehicle-ids", "010,1e3"}).first, -1);
  EXPECT_THAT(octal.ids, ElementsAre(10u, 1000u));  // not 8 (octal), and 1e3 is a number
  TestApp half(false);
  EXPECT_THAT(half.Parse({"--vehicle-ids", "1.5"}).second,
              HasSubstr("prog: --vehicle-ids: '1.5' is not a whole number\n"));
  TestApp large(false);
  EXPECT_THAT(large.Parse({"--vehicle-ids", "99999999999"}).second,
              HasSubstr("prog: --vehicle-ids: '99999999999' is too large\n"));
  TestApp number(true);
  EXPECT_THAT(number.Parse({"play", "x.mcap", "--rate", "fast"}).second,
              HasSubstr("prog play: --rate: 'fast' is not a number\n"));
  TestApp value(false);
  EXPECT_THAT(value.Parse({"--world"}).second, HasSubstr("prog: --world needs a value\n"));
  TestApp argument(true);
  const auto [code, err] = argument.Parse({"record"});
  EXPECT_EQ(code, 2);
  EXPECT_THAT(err, HasSubstr("prog record: OUT is missing: prog record OUT\n"));
  CLI::App spawn{"test"};
  std::vector<double> pose;
  spawn.add_option("--spawn", pose, "pose")->expected(3)->delimiter(',');
  std::vector<std::string> args{"prog", "--spawn", "1,2"};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  std::ostringstream out;
  EXPECT_EQ(cli::Parse(spawn, 3, argv.data(), out), 2);
  EXPECT_THAT(out.str(), HasSubstr("prog: --spawn needs 3 values (written as a,b,c), got 2\n"));
}

// A value that is not one of an option's choices (CLI::IsMember) is told with the choices as a
// person writes them and the nearest one, not as "Wall not in {server,wall}".
TEST(CliErrors, AValueOutsideTheChoicesIsToldWithTheNearest) {
  for (const auto& [value, message] : std::vector<std::pair<std::string, std::string>>{
           {"Wall",
            "prog: --clock: 'Wall' is not one of 'server' or 'wall'; did you mean 'wall'?\n"},
           {"serve",
            "prog: --clock: 'serve' is not one of 'server' or 'wall'; did you mean "
            "'server'?\n"},
           {"sundial", "prog: --clock: 'sundial' is not one of 'server' or 'wall'\n"}}) {
    CLI::App app{"test"};
    std::string clock = "server";
    app.add_option("--clock", clock, "clock")->check(CLI::IsMember({"server", "wall"}));
    std::vector<std::string> args{"/usr/bin/prog", "--clock", value};
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    std::ostringstream err;
    EXPECT_EQ(cli::Parse(app, 3, argv.data(), err), 2) << value;
    EXPECT_THAT(err.str(), HasSubstr(message));
    EXPECT_THAT(err.str(), Not(HasSubstr("not in {")));
  }
}

// The programs themselves: each uses the shared layer.
TEST(CliPrograms, EachProgramNamesTheNearestOptionOrCommand) {
  ExpectUsageErrors(
      {{RunServer, "--wrold facility",
        "vdyn-server: unknown option '--wrold'; did you mean '--world'?"},
       {RunRecorder, "recrod x.mcap",
        "vdyn-recorder: unknown command 'recrod'; did you mean 'record'? (the commands: "
        "record, info, export, plot, play, verify, takeover, recover)"},
       {RunRecorder, "", "vdyn-recorder: choose a command: record, info, export, plot, play,"},
       {RunRecorder, "info x.mcap --rate 2",
        "vdyn-recorder info: option '--rate' is not one of 'vdyn-recorder info'; it belongs to "
        "'vdyn-recorder play'"},
       {RunInput, "plya demo", "vdyn-input: unknown command 'plya'; did you mean 'play'?"},
       {RunInput, "play demo --clokc wall",
        "vdyn-input play: unknown option '--clokc'; did you mean '--clock'?"},
       {RunTelemetry, "--outsim 127.0.0.1:4123 --outsim-hx 50",
        "vdyn-telemetry: unknown option '--outsim-hx'; did you mean '--outsim-hz'?"},
       {RunViewer, "--camra map",
        "vdyn-viewer: unknown option '--camra'; did you mean '--camera'?"}},
      {"were not expected", "unexpected argument"});
}

TEST(CliPrograms, EachProgramRefusesAListWithAnEmptyEntry) {
  // Were a list taken, each program would stop soon and on a domain of its own.
  testing::UseLoopbackDds();
  TempDir dir;
  const std::string domain = " --domain " + std::to_string(testing::FreshDomain());
  const std::string out = (dir / "x.mcap").string();
  ExpectUsageErrors(
      {{RunServer, "--vehicle-ids 1,,2 --duration 1" + domain,
        "vdyn-server: --vehicle-ids '1,,2': entry 2 of the list is empty"},
       {RunServer, "--batch --maneuver demo --duration 1 --spawn 1,2,",
        "vdyn-server: --spawn '1,2,': entry 3 of the list is empty"},
       {RunRecorder, "record " + out + " --duration 1 --vehicles 1,,2" + domain,
        "vdyn-recorder: --vehicles '1,,2': entry 2 of the list is empty"},
       {RunRecorder, "record " + out + " --duration 1 --topics state,,events" + domain,
        "vdyn-recorder: --topics 'state,,events': entry 2 of the list is empty"},
       {RunViewer, "--orbit 10,,5 --hidden --frames 1 --wait 0" + domain,
        "vdyn-viewer: --orbit '10,,5': entry 2 of the list is empty"}});
}

// An id the receivers would refuse in every message (empty or blank, longer than
// limits::kMaxIdBytes, with a control character) is refused at the command line of each client that
// sends it, as vdyn-server's --server-id is.
TEST(CliPrograms, AnIdTheReceiversWouldRefuseIsRefused) {
  // Were an id taken, each program would stop soon and on a domain of its own.
  testing::UseLoopbackDds();
  const std::string domain = " --domain " + std::to_string(testing::FreshDomain());
  ExpectUsageErrors(
      {{RunInput, "--source-id '' play demo --clock wall" + domain,
        "vdyn-input play: --source-id: the source id is empty"},
       {RunInput, "--source-id ' ' play demo --clock wall" + domain,
        "vdyn-input play: --source-id: the source id is empty"},
       {RunInput, "--source-id " + std::string(65, 'x') + " play demo --clock wall" + domain,
        "vdyn-input play: --source-id: the source id is 65 bytes long; at most 64"},
       {RunInput, "--source-id \"$(printf 'rig\\ta')\" play demo --clock wall" + domain,
        "vdyn-input play: --source-id: the source id holds a control character: 'rig\\ta'"},
       {RunRecorder, "play x.mcap --server-id ''",
        "vdyn-recorder play: --server-id: the server id is empty"}});
}

// Every program that takes a vehicle id refuses 0 (no vehicle in a message) with the range of ids,
// as the table of limits writes it (issue 31: `vdyn-input --vehicle-id 0` was accepted).
TEST(CliPrograms, EachProgramRefusesVehicleIdZeroWithTheRange) {
  // Were an id taken, each program would stop soon and on a domain of its own.
  testing::UseLoopbackDds();
  TempDir dir;
  const std::string domain = " --domain " + std::to_string(testing::FreshDomain());
  const std::string file = (dir / "x.mcap").string();
  const std::string range = "vehicle id must be in [1, 4294967295], got 0";
  ExpectUsageErrors(
      {{RunServer, "--vehicle-ids 0 --duration 1" + domain, "--vehicle-ids: " + range},
       {RunServer, "--vehicle-ids 1,0..3 --duration 1" + domain, "--vehicle-ids: " + range},
       {RunInput, "--vehicle-id 0 play demo --clock wall" + domain, "--vehicle-id: " + range},
       {RunTelemetry, "--vehicle-id 0 --outsim 127.0.0.1:4123 --duration 1" + domain,
        "--vehicle-id: " + range},
       {RunViewer, "--follow 0 --hidden --frames 1 --wait 0" + domain, "--follow: " + range},
       {RunRecorder, "record " + file + " --duration 1 --vehicles 1,0" + domain,
        "--vehicles: " + range},
       {RunRecorder, "export " + file + " --csv x.csv --vehicle 0", "--vehicle: " + range},
       {RunRecorder, "plot " + file + " --vehicle 0", "--vehicle: " + range},
       {RunRecorder, "play " + file + " --vehicle 0", "--vehicle: " + range},
       {RunRecorder, "verify " + file + " --vehicle 0", "--vehicle: " + range},
       {RunRecorder, "takeover " + file + " --at 1 --vehicle 0", "--vehicle: " + range},
       {RunRecorder, "takeover " + file + " --at 1 --as 0", "--as: " + range}});
}

// vdyn-server --vehicle-ids takes ranges (1..256): each entry an id or an ascending range of at
// most as many ids as a server runs; a range that goes down or holds more is refused, with why.
TEST(Cli, ServerVehicleIdsTakeRanges) {
  testing::UseLoopbackDds();
  const std::string domain = " --domain " + std::to_string(testing::FreshDomain());
  ExpectServerSays("--vehicle-ids 5..1 --duration 1" + domain, 2,
                   "--vehicle-ids: the range '5..1' goes down; write it as 1..5");
  ExpectServerSays("--vehicle-ids 1..300 --duration 1" + domain, 2,
                   "--vehicle-ids: the range '1..300' holds 300 ids; a server runs at most 256");
  ExpectServerSays("--vehicle-ids 1..x --duration 1" + domain, 2,
                   "--vehicle-ids: 'x' is not a number");
  ExpectServerSays("--vehicle-ids 1..3,2 --duration 1" + domain, 2,
                   "--vehicle-ids: vehicle 2 is listed twice");
  ExpectServerSays("--vehicle-ids 1..3,7,10..11 --duration 0.2" + domain, 0, "6 vehicle(s)");
}

// As many vehicles as a server may run start on facility's free ground (issue 31: --vehicle-ids
// 1..256 was refused, "the body would start inside 'glass_barrier'"), and a world too small for
// the vehicles asked for says how many fit.
TEST(Cli, ServerPlacesItsVehiclesOnFreeGroundOrSaysHowManyFit) {
  testing::UseLoopbackDds();
  TempDir dir;
  const std::string domain = " --domain " + std::to_string(testing::FreshDomain());
  ExpectServerSays("--world facility --vehicle-ids 1..256 --max-vehicles 256 --duration 0.2 "
                   "--no-status" + domain,
                   0, "256 vehicle(s)");
  WriteFile(dir / "square.obj", "v -6 -6 0\nv 6 -6 0\nv 6 6 0\nv -6 6 0\nf 1 2 3\nf 1 3 4\n");
  ExpectServerSays("--world " + (dir / "square.obj").string() +
                       " --spawn 0,0,0 --vehicle-ids 1..5 --duration 0.2 --no-status" + domain,
                   2,
                   "only 3 of the 5 vehicles fit on the free ground of world 'square.obj' within "
                   "400 m of its spawn");
}

// Each program's choices, ranges and lists said the same way: a choice mistyped comes with the
// nearest, a device index with its range as the table of limits writes it, a vehicle listed twice
// as a slip in the list.
TEST(CliPrograms, EachProgramNamesTheNearestChoice) {
  // Were a value taken, each program would stop soon and on a domain of its own.
  testing::UseLoopbackDds();
  TempDir dir;
  const std::string domain = " --domain " + std::to_string(testing::FreshDomain());
  const std::string out = (dir / "x.mcap").string();
  ExpectUsageErrors(
      {{RunServer, "--model Paper --dump-vehicle",
        "vdyn-server: --model: 'Paper' is not one of 'paper' or 'full'; did you mean "
        "'paper'?"},
       {RunServer, "--dump-maneuver dem", "did you mean 'demo'?"},
       {RunInput, "play demo --clock Wall" + domain,
        "vdyn-input play: --clock: 'Wall' is not one of 'server' or 'wall'; did you mean "
        "'wall'?"},
       {RunRecorder, "record " + out + " --duration 1 --compression zst" + domain,
        "vdyn-recorder record: --compression: 'zst' is not one of 'zstd', 'lz4' or 'none'; did "
        "you mean 'zstd'?"},
       {RunRecorder, "record " + out + " --duration 1 --topics stat" + domain,
        "vdyn-recorder record: --topics: 'stat' is not a vdyn topic; did you mean 'state'? "
        "(the topics: state, input, control, control_reply, params, world, events, "
        "diagnostics)"},
       {RunViewer, "--camera Map --hidden --frames 1 --wait 0" + domain,
        "vdyn-viewer: --camera: 'Map' is not one of 'chase', 'driver', 'orbit', 'map', "
        "'north' or 'beside'; did you mean 'map'?"},
       {RunInput, "calibrate --device 300 --timeout 1",
        "vdyn-input calibrate: --device: SDL device index must be in [0, 255], got 300"},
       {RunServer, "--vehicle-ids 1,2,1 --duration 1" + domain,
        "vdyn-server: --vehicle-ids: vehicle 1 is listed twice"}},
      {"not in {"});
  // The help shows whole numbers as such and ranges as the table of limits writes them.
  const Result help = RunInput("drive --help");
  EXPECT_THAT(help.output, HasSubstr("--device INT:[0, 255]"));
  EXPECT_THAT(help.output, HasSubstr("--gears INT:[1, 10]=6"));
}

TEST(CliInput, PlayHelpListsItsOptionsAndTheCommonOnes) {
  const Result r = RunInput("play --help");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("--clock"));
  EXPECT_THAT(r.output, HasSubstr("--loop"));
  EXPECT_THAT(r.output, HasSubstr("Before or after the command: --domain N, --vehicle-id ID"));
}

// --clock wall plays without waiting for a server: without one it says so while playing and at
// the end, and ends with exit code 1 (no server), not silently with 0.
TEST(CliInput, PlayByTheWallClockWithoutAServerSaysSo) {
  testing::UseLoopbackDds();
  TempDir dir;
  WriteFile(dir / "m.csv", "t_s,steer_deg,throttle,brake,cruise_kmh\n0,0,0.2,0,0\n3,0,0.2,0,0\n");
  const std::string domain = std::to_string(testing::FreshDomain());
  const Result r =
      RunInput("--domain " + domain + " play " + (dir / "m.csv").string() + " --clock wall");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("no state of vehicle 1 on domain " + domain +
                                  " after 2 s of playing; is vdyn-server running?"));
  EXPECT_THAT(r.output, HasSubstr("played '" + (dir / "m.csv").string() +
                                  "' to its end (3.0 s, wall clock), but no server took it"));
}

// vdyn-input's loop asks for real-time scheduling where the system permits it and says which, as
// vdyn-server does (issue 31: on a loaded machine the input starved); --rt-priority 0 keeps the
// normal scheduler.
TEST(CliInput, TheLoopsSchedulingIsAskedForAndSaid) {
  testing::UseLoopbackDds();
  TempDir dir;
  WriteFile(dir / "m.csv", "t_s,steer_deg,throttle,brake,cruise_kmh\n0,0,0.2,0,0\n0.2,0,0.2,0,0\n");
  const std::string play = " play " + (dir / "m.csv").string() + " --clock wall";
  const std::string domain = "--domain " + std::to_string(testing::FreshDomain());
  const Result r = RunInput(domain + " --rt-priority 30" + play);
  EXPECT_THAT(r.output, ::testing::AnyOf(HasSubstr("; SCHED_FIFO priority 30"),
                                         HasSubstr("; SCHED_OTHER with 1 ns timer slack "
                                                   "(SCHED_FIFO refused: ")))
      << r.output;
  EXPECT_THAT(RunInput(domain + " --rt-priority 0" + play).output,
              HasSubstr("; SCHED_OTHER (--rt-priority 0)"));
  EXPECT_THAT(RunInput(domain + " --rt-priority 100" + play).output,
              HasSubstr("--rt-priority: SCHED_FIFO priority must be in [0, 99], got 100"));
}

}  // namespace
}  // namespace vdyn
