// vdyn-input as a real process against a real server over loopback DDS (issue: drive it with a
// wheel, pedals and keyboard through SDL2): keyboard driving with real X key events (an Xvfb
// server of the test's own, keys sent by xdotool to the SDL window), the reset key, and ownership
// failover between two vdyn-input processes (a keyboard rig as the primary, a maneuver player as
// the backup). Every wait is on DDS data or a child's exit, bounded.
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <thread>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "dds_wait.h"
#include "process.h"
#include "test_support.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"
#include "vdyn/wheel_input/dds_link.h"

namespace vdyn {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;
using namespace std::chrono_literals;
using testing::Process;
using transport::TopicId;

// An X server of this test's own (Xvfb, no window manager), on a display no other test uses.
class Xvfb {
 public:
  explicit Xvfb(const std::filesystem::path& dir) {
    for (int i = 0; i < 200 && display_ < 0; ++i) {
      const int n = 100 + static_cast<int>((getpid() + i * 7) % 800);
      struct stat st {};
      if (stat(fmt::format("/tmp/.X{}-lock", n).c_str(), &st) == 0) continue;
      auto p = std::make_unique<Process>(
          std::vector<std::string>{"/usr/bin/Xvfb", fmt::format(":{}", n), "-screen", "0",
                                   "800x600x24", "-nolisten", "tcp"},
          dir / fmt::format("xvfb-{}.log", n));
      const std::string socket = fmt::format("/tmp/.X11-unix/X{}", n);
      const auto deadline = std::chrono::steady_clock::now() + 15s;
      while (std::chrono::steady_clock::now() < deadline && p->running() &&
             stat(socket.c_str(), &st) != 0) {
        p->Wait(20ms);
      }
      if (p->running() && stat(socket.c_str(), &st) == 0) {
        display_ = n;
        process_ = std::move(p);
      }
    }
  }
  ~Xvfb() {
    // SIGTERM, so it removes its lock file and socket (the Process would SIGKILL it).
    if (process_) {
      process_->Signal(SIGTERM);
      process_->Wait(10s);
    }
  }
  bool ok() const { return display_ >= 0; }
  std::string display() const { return fmt::format(":{}", display_); }

 private:
  int display_ = -1;
  std::unique_ptr<Process> process_;
};

class WheelNet : public ::testing::Test {
 protected:
  void SetUp() override {
    testing::UseLoopbackDds();
    domain_ = testing::FreshDomain();
    setenv("VDYN_CONFIG_DIR", dir_.path().c_str(), 1);
    unsetenv("SDL_VIDEODRIVER");
  }

  std::unique_ptr<Process> StartServer(const std::string& log = "server.log") {
    return std::make_unique<Process>(
        std::vector<std::string>{testing::ServerBinary(), "--domain", std::to_string(domain_),
                                 "--no-status", "--world", "flat"},
        dir_ / log);
  }
  std::unique_ptr<Process> StartInput(std::vector<std::string> args, const std::string& log) {
    std::vector<std::string> argv = {testing::InputBinary(), "--domain", std::to_string(domain_),
                                     "--wait", "30"};
    argv.insert(argv.end(), args.begin(), args.end());
    return std::make_unique<Process>(argv, dir_ / log);
  }
  // Runs xdotool to its end; its output.
  std::string Xdotool(const std::vector<std::string>& args) {
    std::vector<std::string> argv = {"/usr/bin/xdotool"};
    argv.insert(argv.end(), args.begin(), args.end());
    Process p(argv, dir_ / "xdotool.log");
    EXPECT_TRUE(p.Wait(20s).has_value()) << "xdotool hangs";
    return p.Log();
  }
  // The SDL window of a process (xdotool finds it by the _NET_WM_PID SDL sets).
  std::string WindowOf(Process& p) {
    const auto deadline = std::chrono::steady_clock::now() + 30s;
    while (std::chrono::steady_clock::now() < deadline && p.running()) {
      const std::string out = Xdotool({"search", "--pid", std::to_string(p.pid())});
      const auto end = out.find('\n');
      if (end != std::string::npos && end > 0 && std::isdigit(static_cast<unsigned char>(out[0]))) {
        return out.substr(0, end);
      }
      p.Wait(100ms);
    }
    return {};
  }
  void Key(const std::string& window, const std::string& key, bool down) {
    Xdotool({down ? "keydown" : "keyup", "--window", window, key});
  }

  std::uint32_t domain_ = 0;
  testing::TempDir dir_;
};

// Takes states of vehicle 1 until `done` says so or the timeout passes.
bool StatesUntil(transport::Reader<pb::VehicleState>& states, std::chrono::milliseconds timeout,
                 pb::VehicleState& last, const std::function<bool(const pb::VehicleState&)>& done) {
  bool ok = false;
  return testing::ReadUntil(
      states, timeout,
      [&](const pb::VehicleState& s) {
        if (s.vehicle_id() != 1 || ok) return;
        last = s;
        ok = done(s);
      },
      [&] { return ok; });
}

TEST_F(WheelNet, KeyboardDrivesTheVehicleWithRealKeyEvents) {
  Xvfb x(dir_.path());
  ASSERT_TRUE(x.ok()) << "no Xvfb display";
  setenv("DISPLAY", x.display().c_str(), 1);
  auto server = StartServer();
  const auto shot = dir_ / "keyboard.png";
  auto kb = StartInput(
      {"--source-id", "kb", "keyboard", "--screenshot", shot.string(), "--duration", "300"},
      "keyboard.log");
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  pb::VehicleState s;
  ASSERT_TRUE(
      StatesUntil(states, 30s, s, [](const auto& st) { return st.input().source_id() == "kb"; }))
      << server->Log() << kb->Log();
  const double x0 = s.p_wt_w().x();
  const std::string win = WindowOf(*kb);
  ASSERT_FALSE(win.empty()) << kb->Log();

  // Up held: the throttle ramps to 1 and the car goes.
  Key(win, "Up", true);
  ASSERT_TRUE(StatesUntil(states, 20s, s, [](const auto& st) {
    return st.input().throttle() == 1.0 && st.speed_kmh() > 20.0;
  })) << s.DebugString();
  // Left held: the road wheels turn left (positive).
  Key(win, "Left", true);
  ASSERT_TRUE(StatesUntil(states, 10s, s, [](const auto& st) { return st.input().steer() > 0.02; }))
      << s.input().DebugString();
  EXPECT_EQ(s.input().steer_mode(), pb::STEER_ROAD_WHEEL);
  // Released: the steering returns to the centre by itself.
  Key(win, "Left", false);
  ASSERT_TRUE(StatesUntil(states, 10s, s, [](const auto& st) { return st.input().steer() == 0.0; }))
      << s.input().DebugString();
  Key(win, "Up", false);
  // The brake: the car slows.
  Key(win, "Down", true);
  ASSERT_TRUE(
      StatesUntil(states, 10s, s, [](const auto& st) { return st.input().brake() == 1.0; }));
  const double braking_from = s.speed_kmh();
  ASSERT_TRUE(StatesUntil(states, 10s, s,
                          [&](const auto& st) { return st.speed_kmh() < braking_from - 5; }));
  Key(win, "Down", false);
  // Back to speed, then Backspace: the server resets the vehicle to its spawn pose, at rest.
  Key(win, "w", true);
  ASSERT_TRUE(StatesUntil(states, 20s, s, [&](const auto& st) {
    return st.speed_kmh() > 10 && std::abs(st.p_wt_w().x() - x0) > 5;
  }));
  Key(win, "w", false);
  Key(win, "BackSpace", true);
  Key(win, "BackSpace", false);
  ASSERT_TRUE(StatesUntil(
      states, 20s, s,
      [&](const auto& st) { return st.speed_kmh() < 0.5 && std::abs(st.p_wt_w().x() - x0) < 0.5; }))
      << s.DebugString() << kb->Log();

  // Ctrl+C: a summary with the latency from the key sample to its DDS write, and the screenshot.
  kb->Signal(SIGINT);
  ASSERT_EQ(kb->Wait(20s), 0) << kb->Log();
  EXPECT_THAT(kb->Log(), HasSubstr("sample to DDS write p50"));
  EXPECT_THAT(kb->Log(), HasSubstr("reset requests 1"));
  EXPECT_THAT(kb->Log(), HasSubstr("vehicle 1 reset"));
  ASSERT_TRUE(std::filesystem::exists(shot));
  EXPECT_EQ(testing::ReadFile(shot).substr(1, 3), "PNG");
  if (const char* keep = std::getenv("VDYN_KEEP_SCREENSHOT")) {
    std::filesystem::copy_file(shot, keep, std::filesystem::copy_options::overwrite_existing);
  }
}

// Two vdyn-input processes for one vehicle: a keyboard rig as the primary (strength 20) and a
// maneuver player as the backup (strength 5). The primary dies without a goodbye: the backup drives
// within the input's liveliness lease; the primary comes back and takes over again.
TEST_F(WheelNet, OwnershipFailsOverBetweenTwoRigs) {
  Xvfb x(dir_.path());
  ASSERT_TRUE(x.ok()) << "no Xvfb display";
  setenv("DISPLAY", x.display().c_str(), 1);
  auto server = StartServer();
  const auto backup_csv = dir_ / "backup.csv";
  testing::WriteFile(backup_csv, "t_s,steer_deg,throttle,brake\n0,0,0.2,0\n600,0,0.2,0\n");
  auto backup = StartInput(
      {"--source-id", "backup", "--strength", "5", "play", backup_csv.string(), "--clock", "wall"},
      "backup.log");
  auto primary =
      StartInput({"--source-id", "primary", "--strength", "20", "keyboard", "--duration", "300"},
                 "primary.log");
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  pb::VehicleState s;
  auto until = [&](const std::string& who, std::chrono::milliseconds t) {
    return StatesUntil(states, t, s, [&](const auto& st) { return st.input().source_id() == who; });
  };
  ASSERT_TRUE(until("primary", 30s)) << s.input().DebugString() << primary->Log() << backup->Log();
  EXPECT_EQ(s.input().throttle(), 0.0);  // the keyboard, no key held
  primary->Signal(SIGKILL);
  primary->Wait(10s);
  ASSERT_TRUE(until("backup", 10s)) << s.input().DebugString();
  EXPECT_DOUBLE_EQ(s.input().throttle(), 0.2);
  primary =
      StartInput({"--source-id", "primary", "--strength", "20", "keyboard", "--duration", "300"},
                 "primary2.log");
  ASSERT_TRUE(until("primary", 30s)) << s.input().DebugString() << primary->Log();
}

// Without a display the keyboard cannot be read: a clear message and exit code 2, not a hang.
TEST_F(WheelNet, KeyboardWithoutADisplayEndsWithAMessage) {
  unsetenv("DISPLAY");
  unsetenv("WAYLAND_DISPLAY");
  unsetenv("XDG_RUNTIME_DIR");
  auto server = StartServer();
  auto kb = StartInput({"keyboard"}, "keyboard.log");
  ASSERT_EQ(kb->Wait(60s), 2) << kb->Log();
  EXPECT_THAT(kb->Log(), HasSubstr("the keyboard needs a window, but there is no display (SDL "
                                   "found only its offscreen video driver; is DISPLAY set?)"));
  // One message that helps: no stray one from SDL's Wayland driver before it.
  EXPECT_THAT(kb->Log(), Not(HasSubstr("XDG_RUNTIME_DIR")));
  // drive: no wheel and no display either.
  auto drive = StartInput({"drive"}, "drive.log");
  ASSERT_EQ(drive->Wait(60s), 2) << drive->Log();
  EXPECT_THAT(drive->Log(), HasSubstr("no wheel found, and the keyboard needs a window"));
}

// The rig's first reset follows a server's answer to a hello (a request written before the server
// has discovered the rig's writer reaches no one); later resets go at once.
TEST_F(WheelNet, TheFirstResetFollowsAServersAnswerToAHello) {
  transport::Participant rig(domain_);
  wheel_input::DdsLink link(rig, 1, "rig", 10);
  transport::Participant server_side(domain_);
  testing::AnsweringPeer server(server_side, "fake");
  link.RequestReset();
  ASSERT_TRUE(server.ServeUntil(30s, [&] { return link.resets_accepted() == 1; }));
  ASSERT_GE(server.seen.size(), 2u);
  EXPECT_TRUE(server.seen.front().has_hello());
  EXPECT_TRUE(server.seen.back().has_reset());
  EXPECT_EQ(server.seen.back().vehicle_id(), 1u);
  const std::size_t before = server.seen.size();
  link.RequestReset();
  ASSERT_TRUE(server.ServeUntil(30s, [&] { return link.resets_accepted() == 2; }));
  ASSERT_EQ(server.seen.size(), before + 1) << "no second hello to a server that answered one";
  EXPECT_TRUE(server.seen.back().has_reset());
}

}  // namespace
}  // namespace vdyn
