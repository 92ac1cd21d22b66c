// vdyn-viewer against the real thing: a running vdyn-server (a viewer that joins late draws its
// world; a parameter change is answered; the arrows add up to the wheel force the server
// computed), the vdyn-viewer program's command line, and the whole OpenXR frame loop in the test
// runtime (tests/viewer/xr_runtime) loaded by the real OpenXR loader through XR_RUNTIME_JSON.
#include <gtest/gtest.h>

#include <SDL.h>
#include <openxr/openxr.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "../dds_wait.h"
#include "../process.h"
#include "../test_support.h"
#include "test_runtime.h"
#include "vdyn/base/deadline.h"
#include "vdyn/base/time.h"
#include "vdyn/client/driver_input.h"
#include "vdyn/client/session_view.h"
#include "vdyn/recorder/mcap.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/session.pb.h"
#include "vdyn/transport/control_client.h"
#include "vdyn/viewer/car_model.h"
#include "vdyn/viewer/params_editor.h"
#include "vdyn/viewer/scene.h"
#include "vdyn/viewer/viewer.h"
#include "vdyn/viewer/xr_session.h"
#include "viewer_support.h"

namespace vdyn::testing {
namespace {

using viewer::Image;
using viewer::kPi;

std::map<std::string, std::string> ReadKeyValues(const std::filesystem::path& path) {
  std::map<std::string, std::string> out;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    const auto sp = line.find(' ');
    if (sp == std::string::npos) continue;
    out[line.substr(0, sp)] = line.substr(sp + 1);
  }
  return out;
}

class ViewerProcess : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    xvfb_ = new Xvfb(1280, 800);
    setenv("DISPLAY", xvfb_->display().c_str(), 1);
    UseLoopbackDds();
  }
  static void TearDownTestSuite() {
    delete xvfb_;
    xvfb_ = nullptr;
  }
  static Xvfb* xvfb_;
  TempDir dir_;
};
Xvfb* ViewerProcess::xvfb_ = nullptr;

// Waits (bounded) for a first state of `vehicle` on a domain: the server is up.
bool WaitForServer(std::uint32_t domain, std::uint32_t vehicle, int seconds) {
  transport::Participant p(domain);
  client::SessionView view(p, {});
  return base::PollUntil(
      base::Deadline::After(base::Seconds(seconds)), base::Milliseconds(100),
      [&] {
        view.Poll();
        return view.vehicle(vehicle) != nullptr && view.vehicle(vehicle)->states > 0;
      },
      [&](base::Nanos slice) { (void)view.Wait(base::Chrono(slice)); });
}

TEST_F(ViewerProcess, AViewerThatJoinsLateDrawsTheWorldOfARunningServer) {
  const std::uint32_t domain = FreshDomain();
  Process server({ServerBinary(), "--domain", std::to_string(domain), "--world", "facility",
                  "--duration", "120"},
                 dir_ / "server.log");
  ASSERT_TRUE(WaitForServer(domain, 1, 60)) << server.Log();
  // The world was published once, long before this viewer existed (transient local).
  const auto png = dir_ / "late.png", stats = dir_ / "stats.txt";
  Process viewer({VDYN_VIEWER_BINARY,
                  "--domain",
                  std::to_string(domain),
                  "--camera",
                  "map",
                  "--map-span",
                  "20",
                  "--width",
                  "640",
                  "--height",
                  "480",
                  "--msaa",
                  "0",
                  "--fps",
                  "0",
                  "--frames",
                  "3",
                  "--no-hud",
                  "--hidden",
                  "--wait",
                  "60",
                  "--screenshot",
                  png.string(),
                  "--stats-out",
                  stats.string()},
                 dir_ / "viewer.log");
  const auto code = viewer.Wait(std::chrono::seconds(120));
  ASSERT_TRUE(code.has_value()) << viewer.Log();
  ASSERT_EQ(*code, 0) << viewer.Log();
  const auto kv = ReadKeyValues(stats);
  EXPECT_EQ(kv.at("worlds_accepted"), "1");
  EXPECT_EQ(kv.at("worlds_refused"), "0");
  EXPECT_NE(viewer.Log().find("world 'facility' of server"), std::string::npos) << viewer.Log();
  const auto img = LoadPng(png);
  ASSERT_TRUE(img.has_value());
  // The map is centred on vehicle 1 at its spawn on the test road (8 m wide along X, north up,
  // 12 px per metre): asphalt across the middle, grass 5 m and more to either side. (Both are
  // textured: the pixels are classified, and the means are the surfaces' colours from afar.)
  const int ppm = 480 / 40;
  // (The road starts 12 m west of the spawn: look east of it.)
  const Rect east_road{400, 240 - 3 * ppm, 600, 240 + 3 * ppm};
  const Rect north_ground{0, 0, 500, 240 - 5 * ppm};
  const Rect south_ground{0, 240 + 5 * ppm, 500, 480};
  const RegionStats road = Classify(*img, east_road);
  EXPECT_GT(road.asphalt, road.pixels * 8 / 10) << "not asphalt east of the car";
  const viewer::Rgb8 asphalt = viewer::LookOf(pb::SURFACE_ROAD).colour;
  EXPECT_NEAR(road.g, asphalt.g, 12.0);
  for (const Rect& r : {north_ground, south_ground}) {
    const RegionStats ground = Classify(*img, r);
    EXPECT_EQ(ground.asphalt, 0) << "asphalt north or south of the road";
    EXPECT_GT(ground.grass, ground.pixels * 95 / 100) << "not grass beside the road";
  }
  // And the vehicle in the middle.
  const viewer::Rgb8 car = viewer::VehicleColour(1);
  EXPECT_GT(FindColour(*img, car.r, car.g, car.b, 12, {280, 200, 360, 280}).count, 100);
}

TEST_F(ViewerProcess, AParameterChangeIsAnsweredAndARejectedOneShowsItsReason) {
  const std::uint32_t domain = FreshDomain();
  Process server(
      {ServerBinary(), "--domain", std::to_string(domain), "--world", "flat", "--duration", "120"},
      dir_ / "server.log");
  ASSERT_TRUE(WaitForServer(domain, 1, 60)) << server.Log();
  viewer::ViewerOptions o;
  o.domain = domain;
  o.hidden = true;
  o.fps = 0;
  o.samples = 0;
  o.width = 800;
  o.height = 600;
  viewer::Viewer v(o);
  auto frames_until = [&](const std::function<bool()>& done) {  // a frame, then a look
    const base::Deadline deadline = base::Deadline::After(base::Seconds(60));
    while (!deadline.Passed()) {
      v.Frame();
      if (done()) return true;
    }
    return false;
  };
  ASSERT_TRUE(frames_until([&] {
    const auto* sv = v.session().vehicle(1);
    return v.ready() && sv != nullptr && sv->params.has_value();
  }));
  // The panel open (key P), showing what the transient-local topic holds.
  SDL_Event key{};
  key.type = SDL_KEYDOWN;
  key.key.keysym.sym = SDLK_p;
  SDL_PushEvent(&key);
  v.Frame();
  EXPECT_DOUBLE_EQ(v.session().vehicle(1)->params->mass(), 1500.0);

  using State = viewer::ParamsEditor::Status::State;
  pb::VehicleParams bad;
  bad.set_mass(-1);
  // A request to a server that does not exist waits its whole reply timeout (3 s): while it
  // waits, a second request is refused; then the panel says that nobody answered.
  ASSERT_TRUE(v.params_editor().Submit(1, "no-such-server", bad));
  EXPECT_FALSE(v.params_editor().Submit(1, "", bad)) << "a second request while one waits";
  ASSERT_TRUE(frames_until([&] { return v.params_editor().status().state != State::kPending; }));
  EXPECT_EQ(v.params_editor().status().state, State::kNoReply);
  EXPECT_NE(v.params_editor().status().text.find(
                "server 'no-such-server' answered none of this client's"),
            std::string::npos)
      << v.params_editor().status().text;

  ASSERT_TRUE(v.params_editor().Submit(1, "", bad));
  ASSERT_TRUE(frames_until([&] { return v.params_editor().status().state != State::kPending; }));
  auto s = v.params_editor().status();
  EXPECT_EQ(s.state, State::kRejected) << s.text;
  EXPECT_NE(s.text.find("mass"), std::string::npos) << s.text;
  EXPECT_NE(s.text.find("-1"), std::string::npos) << s.text;
  v.Frame();
  if (const char* d = std::getenv("VDYN_VIEWER_TEST_PNGS")) {
    viewer::WritePng(std::string(d) + "/params-rejected.png", v.Screenshot());
  }

  pb::VehicleParams good;
  good.set_mass(1600);
  ASSERT_TRUE(v.params_editor().Submit(1, "", good));
  ASSERT_TRUE(frames_until([&] { return v.params_editor().status().state != State::kPending; }));
  s = v.params_editor().status();
  EXPECT_EQ(s.state, State::kAccepted) << s.text;
  EXPECT_NE(s.text.find("accepted at step"), std::string::npos);
  // The server publishes the parameters in effect: the viewer sees the new mass.
  EXPECT_TRUE(frames_until([&] { return v.session().vehicle(1)->params->mass() == 1600.0; }));
}

TEST_F(ViewerProcess, TheArrowsOfAWheelAddUpToTheWheelForceTheServerComputed) {
  const std::uint32_t domain = FreshDomain();
  Process server({ServerBinary(), "--domain", std::to_string(domain), "--world", "facility",
                  "--duration", "120"},
                 dir_ / "server.log");
  ASSERT_TRUE(WaitForServer(domain, 1, 60)) << server.Log();
  transport::Participant p(domain);
  client::SessionView view(p, {});
  client::InputPublisher rig(p, 1, "test-rig", 10);
  // Just before the speed bumps (x = -180 m on the test road) at 10 m/s.
  transport::ControlClient control(p, "viewer-test");
  ASSERT_TRUE(control.WaitForServer(std::chrono::seconds(30))) << control.last_error();
  pb::ControlRequest teleport;
  teleport.set_vehicle_id(1);
  teleport.mutable_teleport()->mutable_pose()->set_x(-195);
  teleport.mutable_teleport()->mutable_pose()->set_y(-150);
  teleport.mutable_teleport()->set_speed(10);
  const auto reply = control.Call(teleport, std::chrono::seconds(30));
  ASSERT_TRUE(reply.has_value()) << control.last_error();
  ASSERT_TRUE(reply->accepted()) << reply->reason();
  // Drive, steer and brake over the speed bumps: every force in play, on slopes too.
  int checked = 0, sloped = 0, braking = 0, full = 0;
  const auto deadline = base::MonotonicNow() + base::Seconds(40);
  while (base::MonotonicNow() < deadline && (checked < 400 || sloped < 20 || braking < 20)) {
    const double t = static_cast<double>(checked) * 0.01;
    pb::DriverInput in;
    in.set_throttle(std::fmod(t, 6.0) < 4.0 ? 0.8 : 0.0);
    in.set_brake(std::fmod(t, 6.0) < 4.0 ? 0.0 : 0.4);
    in.set_steer(0.04 * std::sin(t));
    ASSERT_TRUE(rig.Publish(in));
    (void)view.Wait(std::chrono::milliseconds(5));
    view.Poll();
    const auto* sv = view.vehicle(1);
    if (sv == nullptr || sv->states == 0 || std::abs(sv->state.v_wt_b().x()) < 1.0) continue;
    const pb::VehicleState& s = sv->state;
    const viewer::VehicleView vv =
        viewer::BuildVehicleView(s, viewer::GeometryFor(1, nullptr, nullptr));
    for (int w = 0; w < 4; ++w) {
      const pb::WheelState& ws = s.wheels(w);
      if (!ws.contact()) continue;
      viewer::Vec3 sum{};
      for (const viewer::ForceArrow& a : vv.arrows) {
        if (a.wheel == w) sum += a.force_W;
      }
      // The paper model's rolling resistance (no arrow of its own) opposes the rolling like the
      // brake; in the full model it is a torque on the wheel, inside the tire's Fx.
      const viewer::WheelView& wv = vv.wheels[static_cast<std::size_t>(w)];
      const viewer::Vec3 v_T{s.v_wt_w().x(), s.v_wt_w().y(), s.v_wt_w().z()};
      const viewer::Vec3 w_W =
          vv.pose_WB.R * viewer::Vec3{s.w_wb_b().x(), s.w_wb_b().y(), s.w_wb_b().z()};
      const viewer::Vec3 v_B = v_T + viewer::Cross(w_W, wv.contact_W - vv.pose_WB.t);
      const double roll = viewer::Dot(v_B, wv.t_long_W) >= 0 ? 1.0 : -1.0;
      if (s.model() != pb::VEHICLE_MODEL_FULL) sum -= wv.t_long_W * (roll * ws.frr());
      const viewer::Vec3 f{ws.f_w().x(), ws.f_w().y(), ws.f_w().z()};
      ASSERT_LT(viewer::Norm(sum - f), 1e-6 * (1.0 + viewer::Norm(f)))
          << "wheel " << w << " at step " << s.step() << ": arrows add up to (" << sum.x << ", "
          << sum.y << ", " << sum.z << "), f_w is (" << f.x << ", " << f.y << ", " << f.z << ")";
      if (ws.n_w().z() < 0.999) ++sloped;
      if (ws.fb() > 10) ++braking;
      if (s.model() == pb::VEHICLE_MODEL_FULL) ++full;
    }
    ++checked;
  }
  EXPECT_GE(checked, 400);
  EXPECT_GE(sloped, 20) << "no wheel on a slope (the speed bumps)";
  EXPECT_GT(full, 0) << "the server's default, the full model, was not seen";
  EXPECT_GE(braking, 20);
}

TEST_F(ViewerProcess, CommandLineMistakesExitWith2) {
  for (std::vector<std::string> bad :
       std::vector<std::vector<std::string>>{{"--fps", "-1"},
                                             {"--camera", "sideways"},
                                             {"--orbit", "1,2"},
                                             {"--arrow-scale", "nan"},
                                             {"--width", "10"},
                                             {"--msaa", "3.5"},
                                             {"--xr-space", "lying"},
                                             {"--delay", "-5"},
                                             {"--delay", "2000"},
                                             {"--horizon", "tilted"},
                                             {"--quality", "medium"}}) {
    std::vector<std::string> argv = {VDYN_VIEWER_BINARY};
    argv.insert(argv.end(), bad.begin(), bad.end());
    Process p(argv, dir_ / "bad.log");
    const auto code = p.Wait(std::chrono::seconds(30));
    ASSERT_TRUE(code.has_value());
    EXPECT_EQ(*code, 2) << bad[0] << " " << bad[1] << ": " << p.Log();
  }
}

// --quality low and high are what they say (the stats and the log name them); a car model that
// cannot be read is named with its reason and the built-in body is drawn instead.
TEST_F(ViewerProcess, QualityPresetsAreAcceptedAndABrokenCarModelFallsBackToTheBuiltInBody) {
  {
    std::ofstream f(dir_ / "broken.glb", std::ios::binary);
    f << "glTF\x02\x00\x00\x00 truncated";
  }
  struct Case {
    std::string quality, model, expect_log;
  };
  for (const Case& c :
       {Case{"low", "", "quality low (no sun shadows"},
        Case{"high", "", "quality high (sun shadows"},
        Case{"high", (dir_ / "broken.glb").string(), "drawing the built-in body instead"},
        Case{"low", (dir_ / "missing.glb").string(), "drawing the built-in body instead"}}) {
    SCOPED_TRACE(c.quality + " " + c.model);
    const auto stats = dir_ / "stats.txt";
    std::filesystem::remove(stats);
    std::vector<std::string> argv = {VDYN_VIEWER_BINARY,
                                     "--domain",
                                     std::to_string(FreshDomain()),
                                     "--frames",
                                     "1",
                                     "--wait",
                                     "0",
                                     "--quality",
                                     c.quality,
                                     "--stats-out",
                                     stats.string()};
    if (!c.model.empty()) {
      argv.push_back("--car-model");
      argv.push_back(c.model);
    }
    Process p(argv, dir_ / "quality.log");
    const auto code = p.Wait(std::chrono::seconds(60));
    ASSERT_TRUE(code.has_value());
    EXPECT_EQ(*code, 0) << p.Log();
    EXPECT_EQ(ReadKeyValues(stats)["quality"], c.quality);
    EXPECT_NE(p.Log().find(c.expect_log), std::string::npos) << p.Log();
    if (!c.model.empty()) {
      EXPECT_NE(p.Log().find("car model '" + c.model + "'"), std::string::npos) << p.Log();
      EXPECT_NE(p.Log().find("the built-in car body"), std::string::npos) << p.Log();
    }
  }
}

TEST_F(ViewerProcess, WithoutADisplayItSaysSoAndStillDrawsOffscreen) {
  const auto png = dir_ / "offscreen.png";
  Process p(
      {"/usr/bin/env", "-u", "DISPLAY", "-u", "WAYLAND_DISPLAY", VDYN_VIEWER_BINARY, "--domain",
       std::to_string(FreshDomain()), "--frames", "1", "--wait", "0", "--screenshot", png.string()},
      dir_ / "nodisplay.log");
  const auto code = p.Wait(std::chrono::seconds(60));
  ASSERT_TRUE(code.has_value());
  EXPECT_EQ(*code, 0) << p.Log();
  EXPECT_NE(p.Log().find("no display"), std::string::npos) << p.Log();
  EXPECT_TRUE(LoadPng(png).has_value());
}

// --- OpenXR ----------------------------------------------------------------------------------

// Where a world point lands in an eye of the test runtime's headset: the eye's pose in the world
// (axes X right, Y up, Z back) and its field of view; pixel x right, y down.
struct EyeModel {
  viewer::Vec3 position;
  viewer::Vec3 x, y, z;
  double left, right, up, down;  // tangents
};
std::array<double, 2> EyePixel(const EyeModel& e, const viewer::Vec3& p) {
  const viewer::Vec3 d = p - e.position;
  const double xe = viewer::Dot(d, e.x), ye = viewer::Dot(d, e.y), ze = viewer::Dot(d, e.z);
  const double u = xe / -ze, v = ye / -ze;
  return {(u - e.left) / (e.right - e.left) * xrtest::kEyeWidth,
          (e.up - v) / (e.up - e.down) * xrtest::kEyeHeight};
}

// The eyes of a head whose reference-space origin sits at `origin` with OpenXR axes `axes` in
// the world, the head `head_up` metres above it (STAGE) or at it.
std::array<EyeModel, 2> Eyes(const viewer::Vec3& origin, const viewer::Mat3& axes, double head_up) {
  std::array<EyeModel, 2> eyes{};
  for (int e = 0; e < 2; ++e) {
    EyeModel& m = eyes[static_cast<std::size_t>(e)];
    m.x = axes.c[0];
    m.y = axes.c[1];
    m.z = axes.c[2];
    m.position = origin + m.y * head_up + m.x * ((e == 0 ? -0.5 : 0.5) * xrtest::kIpd);
    const double outer = std::tan(xrtest::kAngleOuter), inner = std::tan(xrtest::kAngleInner);
    m.left = e == 0 ? outer : -inner;
    m.right = e == 0 ? inner : -outer;
    m.up = std::tan(xrtest::kAngleUp);
    m.down = std::tan(xrtest::kAngleDown);
  }
  return eyes;
}

class ViewerXr : public ViewerProcess {
 protected:
  // Runs vdyn-viewer in the test runtime's headset on a domain where a test publisher writes the
  // test world and `state`; returns the runtime's report (and its images in dir_).
  std::map<std::string, std::string> RunInHeadset(const pb::VehicleState& state,
                                                  std::vector<std::string> args,
                                                  const std::string& exit_after = "0",
                                                  const std::string& stage = "1") {
    return RunInHeadset(std::vector<pb::VehicleState>{state}, std::move(args), exit_after, stage);
  }
  std::map<std::string, std::string> RunInHeadset(const std::vector<pb::VehicleState>& states,
                                                  std::vector<std::string> args,
                                                  const std::string& exit_after = "0",
                                                  const std::string& stage = "1") {
    return Run(states, {"--xr"}, std::move(args), exit_after, stage);
  }
  // The same viewer on the desktop (no --xr): its screenshot in dir_/desktop.png.
  void RunOnDesktop(const pb::VehicleState& state, std::vector<std::string> args) {
    args.insert(args.end(), {"--screenshot", (dir_ / "desktop.png").string()});
    Run({state}, {}, std::move(args), "0", "1");
  }

 private:
  std::map<std::string, std::string> Run(const std::vector<pb::VehicleState>& states,
                                         const std::vector<std::string>& xr,
                                         const std::vector<std::string>& args,
                                         const std::string& exit_after, const std::string& stage) {
    const std::uint32_t domain = FreshDomain();
    TestPublisher pub(domain);
    EXPECT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
    setenv("XR_RUNTIME_JSON", VDYN_XR_TEST_MANIFEST, 1);
    setenv(xrtest::kEnvOut, dir_.path().c_str(), 1);
    setenv(xrtest::kEnvExitAfter, exit_after.c_str(), 1);
    setenv(xrtest::kEnvStage, stage.c_str(), 1);
    std::vector<std::string> argv = {VDYN_VIEWER_BINARY,
                                     "--domain",
                                     std::to_string(domain),
                                     "--hidden",
                                     "--fps",
                                     "0",
                                     "--msaa",
                                     "0",
                                     "--wait",
                                     "60",
                                     "--stats-out",
                                     (dir_ / "stats.txt").string()};
    argv.insert(argv.end(), xr.begin(), xr.end());
    argv.insert(argv.end(), args.begin(), args.end());
    if (std::find(args.begin(), args.end(), "--width") == args.end()) {
      argv.insert(argv.end(), {"--width", "640", "--height", "400"});
    }
    Process viewer(argv, dir_ / "viewer.log");
    unsetenv("XR_RUNTIME_JSON");
    // The state until the viewer ends (best effort topic: written repeatedly).
    const auto deadline = base::MonotonicNow() + base::Seconds(120);
    std::optional<int> code;
    while (!(code = viewer.Wait(std::chrono::milliseconds(20))) &&
           base::MonotonicNow() < deadline) {
      for (const auto& st : states) pub.State(st);
    }
    EXPECT_TRUE(code.has_value()) << "the viewer did not end: " << viewer.Log();
    EXPECT_EQ(code.value_or(-1), 0) << viewer.Log();
    log_ = viewer.Log();
    if (const char* keep = std::getenv("VDYN_VIEWER_TEST_PNGS")) {
      const std::string name = ::testing::UnitTest::GetInstance()->current_test_info()->name();
      for (const char* f : {"left.png", "right.png", "hud.png"}) {
        std::error_code ec;
        std::filesystem::copy_file(dir_ / f, std::filesystem::path(keep) / (name + "-" + f),
                                   std::filesystem::copy_options::overwrite_existing, ec);
      }
    }
    return ReadKeyValues(dir_ / "report.txt");
  }

 protected:
  std::string log_;
};

// The drive arrow of the LF wheel (blue) in an eye image: the extreme pixel towards which +X of
// the world appears (leftmost in these views) and the arrow's mean row.
struct ArrowInEye {
  int count = 0;
  double tip_x = 0, tip_y = 0, row = 0;
};
ArrowInEye FindDriveArrow(const Image& img, bool plus_x_is_left) {
  const viewer::Rgb8 c = viewer::ForceColour(viewer::ForceKind::kDrive);
  const Blob b = FindColour(img, c.r, c.g, c.b, 12);
  ArrowInEye a;
  a.count = b.count;
  a.row = b.cy;
  const int x = plus_x_is_left ? b.min_x : b.max_x + 1;
  a.tip_x = x;
  const Blob end = FindColour(img, c.r, c.g, c.b, 12, {x - 2, 0, x + 3, img.height});
  a.tip_y = end.cy;
  return a;
}

// The orbit camera's place in the headset, written out: 2.5 m from T at yaw 60 deg and pitch
// 5 deg, a level frame facing T (OpenXR axes: X right, Y up, Z back).
struct Place {
  viewer::Vec3 origin;
  viewer::Mat3 axes;
};
Place OrbitPlace(double yaw_deg, double pitch_deg, double distance) {
  const double y = viewer::Rad(yaw_deg), p = viewer::Rad(pitch_deg);
  const viewer::Vec3 T{0, 0, TestCar::kHeight};
  Place out;
  out.origin = T + viewer::Vec3{std::cos(p) * std::cos(y), std::cos(p) * std::sin(y), std::sin(p)} *
                       distance;
  const viewer::Vec3 forward{-std::cos(y), -std::sin(y), 0}, up{0, 0, 1};
  out.axes.c[0] = viewer::Cross(forward, up);
  out.axes.c[1] = up;
  out.axes.c[2] = -forward;
  return out;
}

TEST_F(ViewerXr, SeatedTheWholeFrameLoopRunsAndEachEyeSeesTheArrowsFromItsOwnPlace) {
  // Seated at the orbit camera's place, 2.5 m from the vehicle: its LF spring arrow ~1.4 m from
  // the eyes, near enough for their 64 mm to show.
  TestVehicle t;
  for (auto& w : t.wheels) w.fp = 0;
  t.wheels[0].fp = 2000;  // LF spring: 1 m up from B at the default scale
  const auto report = RunInHeadset(MakeState(t), {"--xr-space", "seated", "--camera", "orbit",
                                                  "--orbit", "60,5,2.5", "--frames", "12"});
  ASSERT_FALSE(report.empty()) << "no report from the test runtime: " << log_;
  EXPECT_EQ(report.at("lifecycle"), "ok");
  EXPECT_EQ(report.at("states"), "idle ready synchronized visible focused stopping idle exiting");
  EXPECT_EQ(report.at("requirements_before_session"), "1");
  EXPECT_EQ(report.at("binding_context_current"), "1");
  EXPECT_EQ(report.at("requested_exit"), "1");
  EXPECT_EQ(report.at("runtime_exit"), "0");
  EXPECT_GE(std::stoi(report.at("frames_with_projection")), 12);
  EXPECT_EQ(report.at("frames_with_projection"), report.at("frames_with_quad"));
  EXPECT_EQ(report.at("projection_space"),
            std::to_string(static_cast<int>(XR_REFERENCE_SPACE_TYPE_LOCAL)));
  // The HUD is a panel fixed in the reference space (it goes where the place goes), not to the
  // head.
  EXPECT_EQ(report.at("quad_space"),
            std::to_string(static_cast<int>(XR_REFERENCE_SPACE_TYPE_LOCAL)));
  EXPECT_EQ(report.at("session_open"), "0");
  EXPECT_NE(log_.find("runtime 'vdyn test runtime'"), std::string::npos) << log_;

  const auto left = LoadPng(dir_ / "left.png"), right = LoadPng(dir_ / "right.png");
  const auto hud = LoadPng(dir_ / "hud.png");
  ASSERT_TRUE(left && right && hud);
  ASSERT_EQ(left->width, xrtest::kEyeWidth);
  const Place place = OrbitPlace(60, 5, 2.5);
  const auto eyes = Eyes(place.origin, place.axes, 0.0);
  const double scale = viewer::ArrowStyle{}.metres_per_newton;
  const viewer::Vec3 tip{TestCar::kB, TestCar::kBl, TestCar::kGround + 2000 * scale};
  const viewer::Rgb8 g = viewer::ForceColour(viewer::ForceKind::kSpring);
  std::array<double, 2> measured{};
  for (int e = 0; e < 2; ++e) {
    SCOPED_TRACE(e == 0 ? "left eye" : "right eye");
    const Image& img = e == 0 ? *left : *right;
    // The arrow stands up from the LF contact point: its head is its highest pixel.
    const Blob b = FindColour(img, g.r, g.g, g.b, 12);
    ASSERT_GT(b.count, 50) << "no spring arrow in the eye";
    const auto expected = EyePixel(eyes[static_cast<std::size_t>(e)], tip);
    EXPECT_NEAR(b.min_y, expected[1], 3.0);
    const Blob top = FindColour(img, g.r, g.g, g.b, 12, {0, b.min_y, img.width, b.min_y + 3});
    EXPECT_NEAR(top.cx, expected[0], 2.0);
    measured[static_cast<std::size_t>(e)] = top.cx;
  }
  // The eyes see the same scene from 64 mm apart: the arrow shifts between them by the parallax
  // of that offset (and the mirrored field of view), nothing else.
  const auto pl = EyePixel(eyes[0], tip), pr = EyePixel(eyes[1], tip);
  EXPECT_NEAR(measured[0] - measured[1], pl[0] - pr[0], 2.0);
  // Without the offset (both eyes at the head's centre) the shift would differ by the parallax.
  auto centred = eyes;
  centred[0].position = centred[1].position = place.origin;
  const double no_offset = EyePixel(centred[0], tip)[0] - EyePixel(centred[1], tip)[0];
  EXPECT_GT(std::abs((pl[0] - pr[0]) - no_offset), 8.0)
      << "the test would not see a missing offset";
  EXPECT_NE(left->rgba, right->rgba);
  // The HUD quad: the panels drawn on a transparent image.
  const Blob transparent = FindColour(*hud, 0, 0, 0, 0);
  EXPECT_GT(transparent.count, hud->width * hud->height / 4);
  EXPECT_LT(transparent.count, hud->width * hud->height - 5000) << "the HUD is empty";
}

// The HUD's first word (LIVE, green) in an image's top left: its first row, how many rows down to
// the first without green, and its mean column.
struct Word {
  int top = 0, rows = 0;
  double cx = 0;
};
Word Live(const Image& img) {
  const Rect top_left{0, 0, img.width / 2, img.height / 3};
  const Blob green = FindColour(img, 102, 255, 102, 40, top_left);
  Word w;
  if (green.count <= 20) return w;
  w.top = green.min_y;
  w.cx = green.cx;
  while (FindColour(img, 102, 255, 102, 40, {0, w.top + w.rows, img.width / 2, w.top + w.rows + 1})
             .count > 0) {
    ++w.rows;
  }
  return w;
}

TEST_F(ViewerXr, TheHudIsAReadablePanelBelowTheEyesFixedInTheSpaceFacingThem) {
  TestVehicle t;
  const auto report = RunInHeadset(MakeState(t), {"--xr-space", "seated", "--frames", "8",
                                                  "--width", "1280", "--height", "720"});
  ASSERT_FALSE(report.empty()) << log_;
  EXPECT_EQ(report.at("lifecycle"), "ok");
  EXPECT_EQ(report.at("quad_space"),
            std::to_string(static_cast<int>(XR_REFERENCE_SPACE_TYPE_LOCAL)));
  // Where it hangs (the head at the LOCAL origin, looking along -Z): ahead, below the eyes, its
  // face (+Z) turned to them.
  std::istringstream pose(report.at("quad_pose"));
  double x, y, z, qx, qy, qz, qw;
  pose >> x >> y >> z >> qx >> qy >> qz >> qw;
  EXPECT_NEAR(x, 0.0, 1e-6);
  EXPECT_LT(y, -0.1);
  EXPECT_LT(z, -0.5);
  const viewer::Mat3 R = viewer::RotationFromQuat(qw, qx, qy, qz);
  const viewer::Vec3 to_eyes = viewer::Normalized(-viewer::Vec3{x, y, z});
  EXPECT_GT(viewer::Dot(R.c[2], to_eyes), std::cos(viewer::Rad(3)));
  // Readable: the capitals of its first word (LIVE, green) at least as tall in degrees of view
  // as on the desktop at 1280x720. In the headset: LIVE's top and bottom edges on the panel (its
  // axes x right, y up, centred at its pose) seen through the left eye's projection (the head at
  // the LOCAL origin, the runtime's field of view), as the angle between the two rows' rays.
  const auto hud = LoadPng(dir_ / "hud.png");
  ASSERT_TRUE(hud.has_value());
  const Word live = Live(*hud);
  ASSERT_GT(live.rows, 2) << "no LIVE on the HUD";
  std::istringstream size(report.at("quad_size_m"));
  double width_m = 0, height_m = 0;
  size >> width_m >> height_m;
  auto on_panel = [&](double px, double py) {
    return viewer::Vec3{x, y, z} + R.c[0] * ((px / hud->width - 0.5) * width_m) +
           R.c[1] * ((0.5 - py / hud->height) * height_m);
  };
  const EyeModel left = Eyes({0, 0, 0}, viewer::Mat3{}, 0)[0];
  auto elevation = [&](const viewer::Vec3& p) {  // of the ray through p's row in the eye image
    const double row = EyePixel(left, p)[1];
    return std::atan(left.up - row / xrtest::kEyeHeight * (left.up - left.down));
  };
  const double headset_deg = viewer::Deg(elevation(on_panel(live.cx, live.top)) -
                                         elevation(on_panel(live.cx, live.top + live.rows)));
  // The frame is drawn at the runtime's predicted display time (its clock converted): the
  // viewer's last display time is the one the runtime predicted for the last frame drawn.
  const auto stats = ReadKeyValues(dir_ / "stats.txt");
  EXPECT_EQ(stats.at("last_display_mono_ns"), report.at("last_drawn_display_ns"));
  // On the desktop: LIVE's rows of the window's 720, whose height spans the camera's vertical
  // field of view.
  RunOnDesktop(MakeState(t), {"--frames", "8", "--width", "1280", "--height", "720"});
  const auto desktop = LoadPng(dir_ / "desktop.png");
  ASSERT_TRUE(desktop.has_value());
  const Word desk = Live(*desktop);
  ASSERT_GT(desk.rows, 2) << "no LIVE on the desktop's HUD";
  const double fovy = viewer::CameraState{}.fovy;
  const double desktop_deg = viewer::Deg(2 * std::atan(std::tan(0.5 * fovy) * desk.rows / 720.0));
  std::printf(
      "LIVE: %.2f deg in the headset (%d px of the HUD's %d), %.2f deg on the desktop "
      "(%d px of 720)\n",
      headset_deg, live.rows, hud->height, desktop_deg, desk.rows);
  EXPECT_GE(headset_deg, desktop_deg) << "the headset's HUD text is smaller than the desktop's";
}

TEST_F(ViewerXr, StandingBesideTheVehicleTheRuntimeEndsTheSessionAndTheViewerFollows) {
  TestVehicle t;
  for (auto& w : t.wheels) w.fp = 0;
  t.wheels[0].fh = 3000;
  const auto report =
      RunInHeadset(MakeState(t), {"--xr-space", "standing", "--frames", "100000"}, "15");
  ASSERT_FALSE(report.empty()) << log_;
  EXPECT_EQ(report.at("lifecycle"), "ok");
  EXPECT_EQ(report.at("states"), "idle ready synchronized visible focused stopping idle exiting");
  EXPECT_EQ(report.at("runtime_exit"), "1");
  EXPECT_EQ(report.at("requested_exit"), "0");
  EXPECT_EQ(report.at("projection_space"),
            std::to_string(static_cast<int>(XR_REFERENCE_SPACE_TYPE_STAGE)));
  EXPECT_EQ(report.at("session_open"), "0");
  EXPECT_NE(log_.find("session ended"), std::string::npos) << log_;
  // On the floor 6 m to the vehicle's left, facing it: OpenXR X = -X_W (east is to the left),
  // Y = Z_W, Z = +Y_W; the head 1.6 m up.
  viewer::Mat3 axes;
  axes.c[0] = {-1, 0, 0};
  axes.c[1] = {0, 0, 1};
  axes.c[2] = {0, 1, 0};
  const auto eyes = Eyes({0, 6, TestCar::kGround}, axes, xrtest::kStageHeadHeight);
  const double scale = viewer::ArrowStyle{}.metres_per_newton;
  const viewer::Vec3 tip{TestCar::kB + 3000 * scale, TestCar::kBl, TestCar::kGround};
  for (int e = 0; e < 2; ++e) {
    const auto img = LoadPng(dir_ / (e == 0 ? "left.png" : "right.png"));
    ASSERT_TRUE(img.has_value());
    const ArrowInEye a = FindDriveArrow(*img, true);
    ASSERT_GT(a.count, 20);
    const auto expected = EyePixel(eyes[static_cast<std::size_t>(e)], tip);
    EXPECT_NEAR(a.tip_x, expected[0], 3.0) << (e == 0 ? "left" : "right") << " eye";
    EXPECT_NEAR(a.tip_y, expected[1], 3.0) << (e == 0 ? "left" : "right") << " eye";
  }
}

// Seated at the driver's seat with the head moved off the seat and turned (the test runtime's
// kEnvHead); with `recentre`, the key R pressed once frames run. Returns where the tip of the
// side-force arrow of a vehicle 8 m ahead (its LF wheel, pointing left, out of its body) appears
// in the left eye, and where it appears from the seat itself.
struct SeatView {
  double measured_x = 0, measured_y = 0, expected_x = 0, expected_y = 0;
  int count = 0;
};
SeatView ArrowFromTheSeat(const TempDir& dir, bool recentre) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  EXPECT_TRUE(pub.World(MakeWorld("test", kPi / 2, {1, 2})));
  TestVehicle own, ahead;
  for (auto& w : own.wheels) w.fp = 0;
  ahead.id = 2;
  ahead.x = 8;
  for (auto& w : ahead.wheels) w.fp = 0;
  ahead.wheels[0].fy = 3000;
  setenv("XR_RUNTIME_JSON", VDYN_XR_TEST_MANIFEST, 1);
  setenv(xrtest::kEnvOut, dir.path().c_str(), 1);
  setenv(xrtest::kEnvExitAfter, "0", 1);
  setenv(xrtest::kEnvStage, "1", 1);
  setenv(xrtest::kEnvHead, "0.25 0.1 0.15 15", 1);
  {
    viewer::ViewerOptions o;
    o.domain = domain;
    o.hidden = true;
    o.fps = 0;
    o.samples = 0;
    o.width = 640;
    o.height = 400;
    o.xr = true;
    viewer::Viewer v(o);
    EXPECT_TRUE(v.xr_active()) << v.stats().xr_status;
    const auto deadline = base::MonotonicNow() + base::Seconds(60);
    auto frames = [&](std::uint64_t n) {
      const std::uint64_t until = v.stats().xr_frames + n;
      while (v.stats().xr_frames < until && base::MonotonicNow() < deadline) {
        pub.State(MakeState(own));
        pub.State(MakeState(ahead));
        v.Frame();
      }
    };
    while (!(v.ready() && v.vehicle(2) != nullptr) && base::MonotonicNow() < deadline) frames(1);
    frames(3);
    if (recentre) {
      SDL_Event key{};
      key.type = SDL_KEYDOWN;
      key.key.keysym.sym = SDLK_r;
      SDL_PushEvent(&key);
    }
    frames(4);
  }  // the runtime writes its images as the viewer leaves the headset
  unsetenv("XR_RUNTIME_JSON");
  unsetenv(xrtest::kEnvHead);
  SeatView out;
  if (const char* keep = std::getenv("VDYN_VIEWER_TEST_PNGS")) {
    std::error_code ec;
    std::filesystem::copy_file(
        dir / "left.png",
        std::filesystem::path(keep) / (recentre ? "recentred-left.png" : "off-seat-left.png"),
        std::filesystem::copy_options::overwrite_existing, ec);
  }
  const auto img = LoadPng(dir / "left.png");
  EXPECT_TRUE(img.has_value());
  if (!img) return out;
  // The arrow points left (+Y): its tip is its leftmost pixel.
  const viewer::Rgb8 c = viewer::ForceColour(viewer::ForceKind::kSide);
  const Blob b = FindColour(*img, c.r, c.g, c.b, 12);
  out.count = b.count;
  out.measured_x = b.min_x;
  out.measured_y = FindColour(*img, c.r, c.g, c.b, 12, {b.min_x, 0, b.min_x + 3, img->height}).cy;
  // From the seat itself: OpenXR axes X = -Y_B, Y = Z_B, Z = -X_B (the vehicle heads east).
  const pb::WorldDescription world = MakeWorld("test", kPi / 2, {1, 2});
  const viewer::Vec3 eyes_B = viewer::CabinFor(viewer::GeometryFor(1, &world, nullptr)).eyes_B;
  const viewer::Vec3 seat{eyes_B.x, eyes_B.y, eyes_B.z + TestCar::kHeight};
  viewer::Mat3 axes;
  axes.c[0] = {0, -1, 0};
  axes.c[1] = {0, 0, 1};
  axes.c[2] = {-1, 0, 0};
  const double scale = viewer::ArrowStyle{}.metres_per_newton;
  const viewer::Vec3 tip{8 + TestCar::kB, TestCar::kBl + 3000 * scale, TestCar::kGround};
  const auto e = EyePixel(Eyes(seat, axes, 0.0)[0], tip);
  out.expected_x = e[0];
  out.expected_y = e[1];
  return out;
}

TEST_F(ViewerXr, RecentringPutsTheEyesAtTheSeatWhereverTheHeadIs) {
  // Off the seat and turned 15 deg left, the arrow ahead is far from where the seat sees it...
  const SeatView off = ArrowFromTheSeat(dir_, false);
  ASSERT_GT(off.count, 20) << "no arrow in view";
  EXPECT_GT(std::abs(off.measured_x - off.expected_x), 50.0);
  // ... and after R it is where the seat sees it.
  const SeatView centred = ArrowFromTheSeat(dir_, true);
  ASSERT_GT(centred.count, 20);
  EXPECT_NEAR(centred.measured_x, centred.expected_x, 3.0);
  EXPECT_NEAR(centred.measured_y, centred.expected_y, 3.0);
}

TEST_F(ViewerXr, WithoutAStageTheStandingViewStandsOnLocalAtEyeHeight) {
  TestVehicle t;
  const auto report =
      RunInHeadset(MakeState(t), {"--xr-space", "standing", "--frames", "5"}, "0", "0");
  ASSERT_FALSE(report.empty()) << log_;
  EXPECT_EQ(report.at("lifecycle"), "ok");
  EXPECT_EQ(report.at("projection_space"),
            std::to_string(static_cast<int>(XR_REFERENCE_SPACE_TYPE_LOCAL)));
  EXPECT_NE(log_.find("the runtime has no STAGE"), std::string::npos) << log_;
}

// The colour of each of a grid of patches of an image: the per-channel median of each patch.
std::vector<std::array<int, 3>> PatchMedians(const Image& img, int cells) {
  std::vector<std::array<int, 3>> out;
  for (int cy = 0; cy < cells; ++cy) {
    for (int cx = 0; cx < cells; ++cx) {
      std::array<std::vector<int>, 3> ch;
      for (int y = cy * img.height / cells; y < (cy + 1) * img.height / cells; ++y) {
        for (int x = cx * img.width / cells; x < (cx + 1) * img.width / cells; ++x) {
          const std::size_t i = (static_cast<std::size_t>(y) * img.width + x) * 4;
          for (std::size_t c = 0; c < 3; ++c) ch[c].push_back(img.rgba[i + c]);
        }
      }
      std::array<int, 3> m{};
      for (std::size_t c = 0; c < 3; ++c) {
        std::nth_element(ch[c].begin(), ch[c].begin() + ch[c].size() / 2, ch[c].end());
        m[c] = ch[c][ch[c].size() / 2];
      }
      out.push_back(m);
    }
  }
  return out;
}

TEST_F(ViewerXr, EveryOfferedFormatOrderShowsTheColoursOfTheSrgbSwapchain) {
  // The same seated driver's view (sky, road, grass, the cockpit) through runtimes that offer
  // their formats in different orders. The test runtime shows a linear format's values encoded
  // to sRGB, as a compositor does: the eye images it shows must match, patch by patch, those of
  // the sRGB swapchain (whose bytes are the renderer's, as on the desktop).
  TestVehicle t;
  struct Order {
    const char* formats;
    const char* chosen;
    int tolerance;  // per channel, of a patch's median (0..255)
  };
  // The sRGB swapchain first: the reference. 8-bit linear steps are coarse in the dark (the
  // sRGB levels 7..17 all come back as 13, 18..25 as 22): up to 4 levels off in a patch that
  // dark; 16 bits: rounding.
  const Order orders[] = {{"RGBA16F SRGB8_ALPHA8 RGBA8", "SRGB8_ALPHA8", 0},
                          {"RGBA16F RGBA8", "RGBA16F", 1},
                          {"RGBA8", "RGBA8", 5},
                          {"RGBA16 RGBA8", "RGBA16", 1}};
  std::vector<std::array<int, 3>> reference;
  for (const Order& o : orders) {
    SCOPED_TRACE(o.formats);
    setenv(xrtest::kEnvFormats, o.formats, 1);
    const auto report = RunInHeadset(MakeState(t), {"--xr-space", "seated", "--frames", "6"});
    unsetenv(xrtest::kEnvFormats);
    ASSERT_FALSE(report.empty()) << log_;
    EXPECT_EQ(report.at("lifecycle"), "ok");
    // Both eyes and the HUD in the chosen format.
    EXPECT_EQ(report.at("swapchain_formats"),
              std::string(o.chosen) + " " + o.chosen + " " + o.chosen);
    EXPECT_NE(log_.find(std::string("swapchain format GL_") + o.chosen), std::string::npos) << log_;
    const auto left = LoadPng(dir_ / "left.png");
    ASSERT_TRUE(left.has_value());
    const auto patches = PatchMedians(*left, 4);
    if (reference.empty()) {
      reference = patches;
      // The view holds bright sky and dark cockpit alike: a wide range to compare.
      int lo = 255, hi = 0;
      for (const auto& p : patches) lo = std::min(lo, p[1]), hi = std::max(hi, p[1]);
      EXPECT_LT(lo, 60);
      EXPECT_GT(hi, 150);
      continue;
    }
    for (std::size_t i = 0; i < patches.size(); ++i) {
      for (std::size_t c = 0; c < 3; ++c) {
        EXPECT_NEAR(patches[i][c], reference[i][c], o.tolerance)
            << "patch " << i << " channel " << c;
      }
    }
  }
}

TEST_F(ViewerXr, ARuntimeWithNoFormatTheViewerDrawsIntoIsNamedWithWhatItOffers) {
  TestVehicle t;
  setenv(xrtest::kEnvFormats, "RGB10_A2", 1);
  const auto report = RunInHeadset(MakeState(t), {"--xr-space", "seated", "--frames", "2"});
  unsetenv(xrtest::kEnvFormats);
  EXPECT_NE(log_.find("offers no swapchain format this viewer draws into (GL_SRGB8_ALPHA8, "
                      "GL_RGBA16F, GL_RGBA16 or GL_RGBA8); it offers: GL_RGB10_A2"),
            std::string::npos)
      << log_;
  EXPECT_NE(log_.find("showing the desktop window instead"), std::string::npos) << log_;
  ASSERT_FALSE(report.empty()) << log_;
  EXPECT_EQ(report.at("lifecycle"), "ok");
  EXPECT_EQ(report.at("frames_ended"), "0");
  EXPECT_EQ(report.at("session_open"), "0");
}

TEST_F(ViewerProcess, WithoutAnOpenXrRuntimeTheViewerSaysSoAndShowsTheDesktop) {
  setenv("XR_RUNTIME_JSON", (dir_ / "no-such-runtime.json").c_str(), 1);
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  Process viewer({VDYN_VIEWER_BINARY, "--domain", std::to_string(domain), "--xr", "--hidden",
                  "--fps", "0", "--msaa", "0", "--frames", "3", "--wait", "2", "--screenshot",
                  (dir_ / "fallback.png").string(), "--stats-out", (dir_ / "stats.txt").string()},
                 dir_ / "viewer.log");
  unsetenv("XR_RUNTIME_JSON");
  const auto code = viewer.Wait(std::chrono::seconds(120));
  ASSERT_TRUE(code.has_value());
  EXPECT_EQ(*code, 0) << viewer.Log();
  EXPECT_NE(viewer.Log().find("no OpenXR runtime"), std::string::npos) << viewer.Log();
  EXPECT_NE(viewer.Log().find("showing the desktop window instead"), std::string::npos);
  const auto kv = ReadKeyValues(dir_ / "stats.txt");
  EXPECT_EQ(kv.at("xr_frames"), "0");
  EXPECT_EQ(kv.at("xr").rfind("desktop fallback", 0), 0u) << kv.at("xr");
  EXPECT_TRUE(LoadPng(dir_ / "fallback.png").has_value());
}

// Lines of a log that contain `text`.
int LinesWith(const std::string& log, const std::string& text) {
  std::istringstream in(log);
  int n = 0;
  for (std::string line; std::getline(in, line);) n += line.find(text) != std::string::npos;
  return n;
}

TEST_F(ViewerProcess, WithoutAnOpenXrRuntimeOrADisplayItSaysSoOnceWithoutTheLibrariesNoise) {
  // No runtime, no display, no XDG_RUNTIME_DIR (a container, a plain ssh session): the OpenXR
  // loader's own error lines and SDL's Wayland probe would come first; only the viewer's
  // messages that say what to do remain.
  Process viewer(
      {"/usr/bin/env", "-u", "DISPLAY", "-u", "WAYLAND_DISPLAY", "-u", "XDG_RUNTIME_DIR", "-u",
       "XR_LOADER_DEBUG", "XR_RUNTIME_JSON=" + (dir_ / "no-such-runtime.json").string(),
       VDYN_VIEWER_BINARY, "--domain", std::to_string(FreshDomain()), "--xr", "--frames", "1",
       "--wait", "0"},
      dir_ / "viewer.log");
  const auto code = viewer.Wait(std::chrono::seconds(120));
  ASSERT_TRUE(code.has_value());
  EXPECT_EQ(*code, 0) << viewer.Log();
  const std::string log = viewer.Log();
  EXPECT_EQ(LinesWith(log, "OpenXR-Loader"), 0) << log;
  EXPECT_EQ(LinesWith(log, "XDG_RUNTIME_DIR"), 0) << log;
  EXPECT_EQ(LinesWith(log, "no OpenXR runtime"), 1) << log;
  EXPECT_EQ(LinesWith(log, "no display"), 1) << log;
}

// --- the HUD's time and step after a restore ---------------------------------------------------

TEST_F(ViewerProcess, AfterARestoreTheHudsTimeAndStepAgree) {
  // Server a drives vehicle 1; its checkpoint at a step of at least 1000 is restored into server
  // b, which has run for a shorter time: the vehicle's steps and b's clock disagree.
  const std::uint32_t da = FreshDomain(), db = FreshDomain();
  Process a({ServerBinary(), "--domain", std::to_string(da), "--world", "flat", "--duration", "120",
             "--server-id", "a"},
            dir_ / "a.log");
  transport::Participant pa(da);
  transport::DropCounters drops;
  transport::Reader<pb::SessionEvent> events(pa, transport::TopicId::kEvents, &drops);
  std::optional<pb::SessionEvent> checkpoint;
  ASSERT_TRUE(ReadUntil(
      events, std::chrono::seconds(60),
      [&](const pb::SessionEvent& e) {
        if (!checkpoint && e.vehicle_id() == 1 && e.has_checkpoint() && e.step() >= 1000)
          checkpoint = e;
      },
      [&] { return checkpoint.has_value(); }))
      << a.Log();
  Process b({ServerBinary(), "--domain", std::to_string(db), "--world", "flat", "--duration", "120",
             "--server-id", "b", "--vehicle-ids", "2"},
            dir_ / "b.log");
  ASSERT_TRUE(WaitForServer(db, 2, 60)) << b.Log();
  transport::Participant pb_(db);
  transport::ControlClient client(pb_, "test-takeover");
  ASSERT_TRUE(client.WaitForServer(std::chrono::seconds(30), "b")) << client.last_error();
  pb::ControlRequest r;
  r.set_vehicle_id(1);
  r.set_server_id("b");
  auto* rs = r.mutable_restore();
  *rs->mutable_state() = checkpoint->checkpoint().state();
  *rs->mutable_params() = checkpoint->checkpoint().params();
  *rs->mutable_input() = checkpoint->checkpoint().input();
  const auto reply = client.Call(r, std::chrono::seconds(30));
  ASSERT_TRUE(reply.has_value()) << client.last_error();
  ASSERT_TRUE(reply->accepted()) << reply->reason();

  viewer::ViewerOptions o;
  o.domain = db;
  o.follow = 1;
  o.hidden = true;
  o.fps = 0;
  o.samples = 0;
  o.width = 800;
  o.height = 600;
  viewer::Viewer v(o);
  for (const base::Deadline until = base::Deadline::After(base::Seconds(60)); !until.Passed();) {
    v.Frame();
    const auto* s = v.shown_state(1);
    if (s != nullptr && s->step() > checkpoint->step()) break;
  }
  const pb::VehicleState* s = v.shown_state(1);
  ASSERT_NE(s, nullptr);
  ASSERT_GT(s->step(), checkpoint->step());
  ASSERT_NE(s->sim_time_ns(), static_cast<std::int64_t>(s->step()) * s->step_ns())
      << "b's clock and the vehicle's steps agree anyway: the test shows nothing";
  // The HUD's line: "... sim time T s   step N   server clock C s", T the step's time.
  std::string line;
  for (const std::string& l : v.hud_text()) {
    if (l.find("sim time") != std::string::npos) line = l;
  }
  ASSERT_FALSE(line.empty());
  double t_s = 0, clock_s = 0;
  unsigned long long step = 0;
  const auto at = line.find("sim time");
  ASSERT_EQ(std::sscanf(line.c_str() + at, "sim time %lf s step %llu server clock %lf s", &t_s,
                        &step, &clock_s),
            3)
      << line;
  EXPECT_NEAR(t_s, static_cast<double>(step) * 1e-3, 5e-4) << line;
  EXPECT_NEAR(clock_s, static_cast<double>(s->sim_time_ns()) * 1e-9, 5e-4) << line;
  EXPECT_NE(std::lround(t_s * 1000), std::lround(clock_s * 1000)) << line;
}

// --- playback ------------------------------------------------------------------------------

// A recording of server 'recorded': a small square world and 3 s of vehicle 1 rolling at 1 m/s.
void WriteDrive(const std::filesystem::path& path) {
  using transport::TopicId;
  mcap::Writer w(path, {});
  auto channel = [&](TopicId t, std::uint32_t key) {
    const auto* d = recorder::PayloadDescriptor(t);
    const std::uint16_t s =
        w.AddSchema(d->full_name(), "protobuf", recorder::FileDescriptorSetOf(d));
    return w.AddChannel(s, recorder::ChannelTopic(t, key), "protobuf",
                        recorder::ChannelMetadata(t, key));
  };
  auto put = [&](std::uint16_t ch, std::uint64_t t, const google::protobuf::Message& m) {
    const std::string b = m.SerializeAsString();
    w.WriteMessage(ch, 0, t, t, {reinterpret_cast<const std::uint8_t*>(b.data()), b.size()});
  };
  const std::uint64_t t0 = 1'800'000'000'000'000'000ull;
  put(channel(TopicId::kWorld, transport::ServerKey("recorded")), t0,
      MakeWorld("recorded", kPi / 2));
  const std::uint16_t state = channel(TopicId::kState, 1);
  for (std::uint64_t i = 1; i <= 3000; ++i) {
    TestVehicle tv;
    tv.server = "recorded";
    tv.step = i;
    tv.x = 0.001 * static_cast<double>(i);
    tv.speed = 1;
    put(state, t0 + i * 1'000'000, MakeState(tv));
  }
  w.Close();
}

TEST_F(ViewerProcess, APlaybackIsRecognisedWithoutAFlagAndNamesItsRecording) {
  const auto file = dir_ / "drive.mcap";
  WriteDrive(file);
  const std::uint32_t domain = FreshDomain();
  Process player(
      {RecorderBinary(), "play", file.string(), "--domain", std::to_string(domain), "--loop"},
      dir_ / "play.log");
  // The viewer joins once the playback runs: it learns what the player is from its announcement
  // of every second, not from the one at the start.
  ASSERT_TRUE(WaitForServer(domain, 1, 60)) << player.Log();
  viewer::ViewerOptions o;
  o.domain = domain;
  o.hidden = true;
  o.fps = 0;
  o.samples = 0;
  o.width = 800;
  o.height = 600;
  ASSERT_FALSE(o.playback);
  viewer::Viewer v(o);
  auto first = [&] { return v.hud_text().empty() ? std::string() : v.hud_text().front(); };
  for (const base::Deadline until = base::Deadline::After(base::Seconds(60)); !until.Passed();) {
    v.Frame();
    if (v.ready() && first().rfind("PLAYBACK", 0) == 0) break;
  }
  EXPECT_EQ(first().rfind("PLAYBACK", 0), 0u) << first() << "\n" << player.Log();
  EXPECT_NE(first().find("recording 'drive.mcap'"), std::string::npos) << first();
  EXPECT_NE(first().find("server 'recorded'"), std::string::npos) << first();
}

}  // namespace
}  // namespace vdyn::testing
