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

#include "../process.h"
#include "../test_support.h"
#include "test_runtime.h"
#include "vdyn/base/time.h"
#include "vdyn/client/driver_input.h"
#include "vdyn/client/session_view.h"
#include "vdyn/transport/control_client.h"
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
  const auto deadline = base::MonotonicNow() + base::Seconds(seconds);
  while (base::MonotonicNow() < deadline) {
    view.Wait(std::chrono::milliseconds(100));
    view.Poll();
    if (view.vehicle(vehicle) != nullptr && view.vehicle(vehicle)->states > 0) return true;
  }
  return false;
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
  // 12 px per metre): road across the middle, open ground 5 m and more to either side.
  const viewer::Rgb8 road = viewer::LookOf(pb::SURFACE_ROAD).colour;
  const viewer::Rgb8 ground = viewer::LookOf(pb::SURFACE_GROUND).colour;
  const int ppm = 480 / 40;
  // (The road starts 12 m west of the spawn: look east of it.)
  const Rect east_road{400, 240 - 3 * ppm, 600, 240 + 3 * ppm};
  const Rect north_ground{0, 0, 500, 240 - 5 * ppm};
  const Rect south_ground{0, 240 + 5 * ppm, 500, 480};
  EXPECT_GT(FindColour(*img, road.r, road.g, road.b, 8, east_road).count, 200 * 5 * ppm);
  EXPECT_EQ(FindColour(*img, road.r, road.g, road.b, 8, north_ground).count, 0);
  // The grid darkens lines: most of the ground is its colour.
  EXPECT_GT(FindColour(*img, ground.r, ground.g, ground.b, 8, north_ground).count, 500 * 150);
  EXPECT_GT(FindColour(*img, ground.r, ground.g, ground.b, 8, south_ground).count, 500 * 150);
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
  auto frames_until = [&](const std::function<bool()>& done) {
    const auto deadline = base::MonotonicNow() + base::Seconds(60);
    while (base::MonotonicNow() < deadline) {
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
  ASSERT_TRUE(v.params_editor().Submit(1, "", bad));
  EXPECT_FALSE(v.params_editor().Submit(1, "", bad)) << "a second request while one waits";
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
    view.Wait(std::chrono::milliseconds(5));
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
                                             {"--xr-space", "lying"}}) {
    std::vector<std::string> argv = {VDYN_VIEWER_BINARY};
    argv.insert(argv.end(), bad.begin(), bad.end());
    Process p(argv, dir_ / "bad.log");
    const auto code = p.Wait(std::chrono::seconds(30));
    ASSERT_TRUE(code.has_value());
    EXPECT_EQ(*code, 2) << bad[0] << " " << bad[1] << ": " << p.Log();
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
                                     "--xr",
                                     "--hidden",
                                     "--fps",
                                     "0",
                                     "--msaa",
                                     "0",
                                     "--width",
                                     "640",
                                     "--height",
                                     "400",
                                     "--wait",
                                     "60",
                                     "--stats-out",
                                     (dir_ / "stats.txt").string()};
    argv.insert(argv.end(), args.begin(), args.end());
    Process viewer(argv, dir_ / "viewer.log");
    unsetenv("XR_RUNTIME_JSON");
    // The state until the viewer ends (best effort topic: written repeatedly).
    const auto deadline = base::MonotonicNow() + base::Seconds(120);
    std::optional<int> code;
    while (!(code = viewer.Wait(std::chrono::milliseconds(20))) &&
           base::MonotonicNow() < deadline) {
      pub.State(state);
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

TEST_F(ViewerXr, SeatedTheWholeFrameLoopRunsAndEachEyeSeesTheArrowsFromItsOwnPlace) {
  TestVehicle t;
  for (auto& w : t.wheels) w.fp = 0;
  t.wheels[0].fp = 2000;  // LF spring: 1 m up from B at the default scale
  const auto report = RunInHeadset(MakeState(t), {"--xr-space", "seated", "--frames", "12"});
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
  EXPECT_EQ(report.at("quad_space"),
            std::to_string(static_cast<int>(XR_REFERENCE_SPACE_TYPE_VIEW)));
  EXPECT_EQ(report.at("session_open"), "0");
  EXPECT_NE(log_.find("runtime 'vdyn test runtime'"), std::string::npos) << log_;

  const auto left = LoadPng(dir_ / "left.png"), right = LoadPng(dir_ / "right.png");
  const auto hud = LoadPng(dir_ / "hud.png");
  ASSERT_TRUE(left && right && hud);
  ASSERT_EQ(left->width, xrtest::kEyeWidth);
  // The seated space: at the driver's seat (body frame, X forward, Y left, Z up), OpenXR axes
  // X = -Y_B, Y = Z_B, Z = -X_B; the vehicle stands at the origin heading east.
  const viewer::CameraState cam;
  const viewer::Vec3 seat{cam.seat_B.x, cam.seat_B.y, cam.seat_B.z + TestCar::kHeight};
  viewer::Mat3 axes;
  axes.c[0] = {0, -1, 0};
  axes.c[1] = {0, 0, 1};
  axes.c[2] = {-1, 0, 0};
  const auto eyes = Eyes(seat, axes, 0.0);
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
  centred[0].position = centred[1].position = seat;
  const double no_offset = EyePixel(centred[0], tip)[0] - EyePixel(centred[1], tip)[0];
  EXPECT_GT(std::abs((pl[0] - pr[0]) - no_offset), 8.0)
      << "the test would not see a missing offset";
  EXPECT_NE(left->rgba, right->rgba);
  // The HUD quad: the panels drawn on a transparent image.
  const Blob transparent = FindColour(*hud, 0, 0, 0, 0);
  EXPECT_GT(transparent.count, hud->width * hud->height / 4);
  EXPECT_LT(transparent.count, hud->width * hud->height - 5000) << "the HUD is empty";
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

}  // namespace
}  // namespace vdyn::testing
