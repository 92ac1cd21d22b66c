// vdyn-viewer as an application: motion between states (drawn at a display time, interpolated),
// the horizon lock of the chase and orbit cameras and their places in a headset, labels that never
// overlap, the driver camera's view of the road, the forces legend, the parameters panel (labels
// from the one table, keys typed into it) and a --follow of a vehicle that is not there. The
// closed forms are written out here, not taken from the viewer.
#include <gtest/gtest.h>

#include <SDL.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <set>

#include "../process.h"
#include "../test_support.h"
#include "vdyn/base/limits.h"
#include "vdyn/base/time.h"
#include "vdyn/viewer/camera.h"
#include "vdyn/viewer/car_model.h"
#include "vdyn/viewer/cockpit.h"
#include "vdyn/viewer/labels.h"
#include "vdyn/viewer/motion.h"
#include "vdyn/viewer/params_editor.h"
#include "vdyn/viewer/scene.h"
#include "vdyn/viewer/viewer.h"
#include "viewer_support.h"

namespace vdyn::testing {
namespace {

using viewer::CameraMode;
using viewer::Image;
using viewer::kPi;
using viewer::Vec3;
using viewer::Viewer;
using viewer::ViewerOptions;

// --- motion --------------------------------------------------------------------------------

// A state of vehicle 1 at step `step` (1 ms steps), at (x, y) heading `yaw`, rolling at `speed`,
// its LF spring force `fp`.
pb::VehicleState At(std::uint64_t step, double x, double y, double yaw, double speed, double fp) {
  TestVehicle t;
  t.step = step;
  t.x = x;
  t.y = y;
  t.yaw = yaw;
  t.speed = speed;
  t.wheels[0].fp = fp;
  return MakeState(t);
}

TEST(Motion, HalfWayBetweenTwoStatesInTimeTheVehicleIsHalfWayThere) {
  // Two states 20 ms apart (steps 1000 and 1020): the car drove 1 m along X at 50 m/s, turned
  // from 0.1 to 0.3 rad and its LF spring force rose from 3000 to 4000 N.
  const std::int64_t s0 = 5'000'000'000;  // source stamps, ns
  viewer::StateHistory h;
  h.Add(At(1000, 0.0, 0.0, 0.1, 50, 3000), s0, s0 + 1'000'000);
  h.Add(At(1020, 1.0, 0.2, 0.3, 50, 4000), s0 + 20'000'000, s0 + 21'000'000);
  // A frame due on the screen at D shows D - offset - delay: half-way when D is 10 ms past the
  // first state plus the offset (1 ms of transit seen) and the delay.
  viewer::ClockOffset clock;
  clock.Observe(s0, s0 + 1'000'000);
  clock.Observe(s0 + 20'000'000, s0 + 23'000'000);  // a slower transit: the offset stays 1 ms
  // (It may rise by 1 ms per second between observations: 23 us here.)
  ASSERT_NEAR(clock.offset_ns(), 1'000'000, 25'000);
  const std::int64_t delay = viewer::kDefaultPresentationDelayNs;
  const std::int64_t display = s0 + 10'000'000 + clock.offset_ns() + delay;
  const auto sample = h.At(display - clock.offset_ns() - delay);
  ASSERT_NE(sample.a, nullptr);
  ASSERT_NE(sample.b, nullptr);
  EXPECT_DOUBLE_EQ(sample.u, 0.5);
  pb::VehicleState mid;
  viewer::InterpolateState(*sample.a, *sample.b, sample.u, mid);
  EXPECT_DOUBLE_EQ(mid.p_wt_w().x(), 0.5);
  EXPECT_DOUBLE_EQ(mid.p_wt_w().y(), 0.1);
  EXPECT_DOUBLE_EQ(mid.wheels(0).fp(), 3500);
  EXPECT_DOUBLE_EQ(mid.wheels(0).p_b_w().x(),
                   0.5 * (sample.a->wheels(0).p_b_w().x() + sample.b->wheels(0).p_b_w().x()));
  // The orientation by slerp: half the turn about the vertical (0.2 rad), a unit quaternion.
  const pb::Quat& q = mid.q_wb();
  EXPECT_NEAR(q.w(), std::cos(0.1), 1e-12);
  EXPECT_NEAR(q.z(), std::sin(0.1), 1e-12);
  EXPECT_NEAR(q.w() * q.w() + q.z() * q.z(), 1.0, 1e-12);
  EXPECT_NEAR(mid.rpy().z(), 0.2, 1e-12);
  // Discrete values are the earlier state's until the later one is reached.
  EXPECT_EQ(mid.step(), 1000u);
  EXPECT_EQ(mid.sim_time_ns(), 1'000'000'000);
  // The drawn view: half-way along, turned half-way.
  const viewer::VehicleView v =
      viewer::BuildVehicleView(mid, viewer::GeometryFor(1, nullptr, nullptr));
  EXPECT_NEAR(v.yaw, 0.2, 1e-12);
  EXPECT_NEAR(v.pose_WB.t.x, 0.5, 1e-12);

  // Before the first state: the first; after the last: the last, as it is (held, never
  // extrapolated).
  EXPECT_EQ(h.At(s0 - 5).b, nullptr);
  EXPECT_EQ(h.At(s0 - 5).a->step(), 1000u);
  const auto held = h.At(s0 + 500'000'000);
  EXPECT_EQ(held.b, nullptr);
  EXPECT_EQ(held.a->step(), 1020u);
  EXPECT_EQ(held.source_ns, s0 + 20'000'000);
}

TEST(Motion, HeadingsAcrossTheBackTurnTheShortWayRound) {
  // From 3.1 rad to -3.1 rad is 0.083 rad through pi, not 6.2 rad through 0.
  pb::VehicleState a = At(10, 0, 0, 3.1, 10, 3000), b = At(11, 0, 0, -3.1, 10, 3000);
  pb::VehicleState mid;
  viewer::InterpolateState(a, b, 0.5, mid);
  EXPECT_NEAR(std::abs(mid.rpy().z()), kPi, 1e-9);
  const viewer::VehicleView v =
      viewer::BuildVehicleView(mid, viewer::GeometryFor(1, nullptr, nullptr));
  EXPECT_NEAR(std::abs(v.yaw), kPi, 1e-9);
}

TEST(Motion, StatesOfTwoLivesAreNeverBlended) {
  const std::int64_t s0 = 1'000'000'000;
  // A restore: the step jumps to a recording's (7779) while the server's clock goes on (5.989 s).
  pb::VehicleState before = At(5988, 0, 0, 0, 0, 3000);
  pb::VehicleState restored = At(7779, 0.001, 0, 0, 0, 3000);  // (restored where it was)
  restored.set_sim_time_ns(5'989'000'000);
  before.set_sim_time_ns(5'988'000'000);
  EXPECT_FALSE(viewer::Continuous(before, restored));
  // A teleport: steps go on, the car is 40 m away 1 ms later.
  EXPECT_FALSE(viewer::Continuous(At(100, 0, 0, 0, 10, 3000), At(101, 40, 0, 0, 10, 3000)));
  // A drive: 1 ms at 10 m/s is 1 cm.
  EXPECT_TRUE(viewer::Continuous(At(100, 0, 0, 0, 10, 3000), At(101, 0.01, 0, 0, 10, 3000)));
  viewer::StateHistory h;
  h.Add(before, s0, s0);
  h.Add(restored, s0 + 1'000'000, s0 + 1'000'000);
  const auto s = h.At(s0 + 500'000);
  EXPECT_EQ(s.b, nullptr) << "blended across a restore";
  EXPECT_EQ(s.a->step(), 5988u);
  // A step back (a recording sought back, a restarted server): the history starts afresh.
  h.Add(At(10, 0, 0, 0, 0, 3000), s0 + 2'000'000, s0 + 2'000'000);
  EXPECT_EQ(h.size(), 1u);
  // A repeat of the newest is not a new state.
  h.Add(At(10, 0, 0, 0, 0, 3000), s0 + 3'000'000, s0 + 3'000'000);
  EXPECT_EQ(h.size(), 1u);
}

TEST(Motion, ThePublishersClockIsFoundByTheShortestTransitAndFollowedWhenItDrifts) {
  viewer::ClockOffset c;
  // Transits of 3, 1 and 2 ms (the other machine's clock 100 ms behind): 100 + 1 ms.
  const std::int64_t skew = 100'000'000;
  c.Observe(0, skew + 3'000'000);
  c.Observe(10'000'000, 10'000'000 + skew + 1'000'000);
  c.Observe(20'000'000, 20'000'000 + skew + 2'000'000);
  EXPECT_NEAR(c.offset_ns(), skew + 1'000'000, 20'000);  // (+1 ms per second since: 10 us)
  // The clocks moved 50 ms apart: followed at 1 ms per second (60 s later, fully).
  std::int64_t t = 20'000'000;
  for (int i = 0; i < 600; ++i) {
    t += 100'000'000;
    c.Observe(t, t + skew + 51'000'000);
  }
  EXPECT_EQ(c.offset_ns(), skew + 51'000'000);
}

// --- cameras: the horizon lock and a headset's places ----------------------------------------

// A vehicle at (3, 4) heading 30 deg, rolled 10 deg and pitched 5 deg.
viewer::VehicleView Tilted() {
  viewer::VehicleView v;
  v.yaw = viewer::Rad(30);
  v.pose_WB.R = viewer::RotationZ(v.yaw) * viewer::RotationAxisAngle({0, 1, 0}, viewer::Rad(5)) *
                viewer::RotationAxisAngle({1, 0, 0}, viewer::Rad(10));
  v.pose_WB.t = {3, 4, 0.6};
  return v;
}

// The camera's right and up axes in the world (from its view matrix: rows of the rotation).
std::array<Vec3, 2> RightUp(const viewer::Mat4& view) {
  return {Vec3{view(0, 0), view(0, 1), view(0, 2)}, Vec3{view(1, 0), view(1, 1), view(1, 2)}};
}

TEST(Cameras, LockedChaseAndOrbitKeepTheHorizonLevelUnlockedTheyRollAndPitchWithTheBody) {
  const viewer::VehicleView car = Tilted();
  viewer::CameraScene scene;
  scene.followed = &car;
  for (CameraMode mode : {CameraMode::kChase, CameraMode::kOrbit}) {
    SCOPED_TRACE(std::string(viewer::CameraName(mode)));
    viewer::CameraState c;
    c.mode = mode;
    // Locked: the screen's horizontal is level (its right axis has no vertical part).
    const auto locked = RightUp(viewer::ComputeCamera(c, scene, 640, 480).view);
    EXPECT_NEAR(locked[0].z, 0.0, 1e-9);
    // A headset's place: a level frame, up the world's up.
    const viewer::Pose place = viewer::XrPlace(c, scene);
    EXPECT_NEAR(place.R.c[1].z, 1.0, 1e-9);
    EXPECT_NEAR(place.R.c[0].z, 0.0, 1e-9);
    // Unlocked: the right axis tilts as the body's does, the place's up is the body's Z.
    c.horizon_locked = false;
    const auto body = RightUp(viewer::ComputeCamera(c, scene, 640, 480).view);
    const Vec3 tilt_right = viewer::Tilt(car.pose_WB, car.yaw) * (locked[0]);
    EXPECT_NEAR(body[0].x, tilt_right.x, 1e-9);
    EXPECT_NEAR(body[0].y, tilt_right.y, 1e-9);
    EXPECT_NEAR(body[0].z, tilt_right.z, 1e-9);
    EXPECT_GT(std::abs(body[0].z), 0.1);  // 10 deg of roll shows
    const viewer::Pose moving = viewer::XrPlace(c, scene);
    const Vec3 z_B = car.pose_WB.R.c[2];
    EXPECT_NEAR(viewer::Dot(moving.R.c[1], z_B), 1.0, 1e-9);
  }
  // The driver's seat always moves with the body: its place's axes are the body's.
  viewer::CameraState d;
  d.mode = CameraMode::kDriver;
  const viewer::Pose seat = viewer::XrPlace(d, scene);
  EXPECT_NEAR(viewer::Dot(seat.R.c[2], -car.pose_WB.R.c[0]), 1.0, 1e-9);  // looks along X_B
  EXPECT_NEAR(viewer::Dot(seat.R.c[1], car.pose_WB.R.c[2]), 1.0, 1e-9);
  const Vec3 eye = car.pose_WB * viewer::CabinFor(car.geometry).eyes_B;
  EXPECT_NEAR(viewer::Norm(seat.t - eye), 0.0, 1e-12);
}

TEST(Cameras, BesideStandsOnTheGroundToTheVehiclesLeftAtEyeHeightFacingIt) {
  viewer::VehicleView car;
  car.yaw = viewer::Rad(90);  // heading north: its left is west
  car.pose_WB.R = viewer::RotationZ(car.yaw);
  car.pose_WB.t = {10, 20, 0.6};
  car.ground_z = 0.02;
  viewer::CameraScene scene;
  scene.followed = &car;
  viewer::CameraState c;
  c.mode = CameraMode::kBeside;
  const viewer::Pose p = viewer::XrPlace(c, scene);
  EXPECT_NEAR(p.t.x, 10 - 6, 1e-9);
  EXPECT_NEAR(p.t.y, 20, 1e-9);
  EXPECT_NEAR(p.t.z, 0.02 + 1.6, 1e-9);
  // Facing the vehicle (east): OpenXR's -Z is forward.
  EXPECT_NEAR(-p.R.c[2].x, 1.0, 1e-9);
}

// --- labels --------------------------------------------------------------------------------

TEST(Labels, NoTwoBoxesOverlapHoweverTheAnchorsCrowd) {
  // 200 labels of landmarks near the horizon: anchors within a 300 x 20 pixel strip.
  std::vector<viewer::LabelRequest> r;
  for (int i = 0; i < 200; ++i) {
    r.push_back({"landmark " + std::to_string(i), 200.0f + static_cast<float>((i * 37) % 300),
                 300.0f + static_cast<float>((i * 11) % 20), 70, 13, 40.0 + i, 0});
  }
  r.push_back({"#1", 350, 310, 16, 13, 8.0, 2});  // the followed vehicle among them
  const auto placed = viewer::LayoutLabels(r, 640, 480);
  ASSERT_FALSE(placed.empty());
  for (std::size_t i = 0; i < placed.size(); ++i) {
    const auto& b = placed[i].box;
    EXPECT_TRUE(b.x0 >= 0 && b.y0 >= 0 && b.x1 <= 640 && b.y1 <= 480);
    for (std::size_t j = i + 1; j < placed.size(); ++j) {
      EXPECT_FALSE(viewer::Overlap(b, placed[j].box))
          << r[placed[i].request].text << " and " << r[placed[j].request].text;
    }
  }
  // The followed vehicle's label comes first and always gets its place.
  EXPECT_EQ(r[placed.front().request].text, "#1");
  // Nor under the HUD's panels: a label whose places are all under one is left out, one with a
  // free place takes it.
  const std::vector<viewer::LabelBox> hud = {{0, 0, 300, 200}};
  const auto under = viewer::LayoutLabels(
      {{"hidden", 150, 100, 40, 13, 10, 0}, {"edge", 302, 100, 40, 13, 10, 0}}, 640, 480, hud);
  ASSERT_EQ(under.size(), 1u);
  EXPECT_EQ(under[0].request, 1u);
  EXPECT_FALSE(viewer::Overlap(under[0].box, hud[0]));
  // Far ones fade: full up to fade_start_m, gone by fade_end_m.
  const viewer::LabelStyle style;
  std::vector<viewer::LabelRequest> fade = {
      {"near", 100, 100, 30, 13, style.fade_start_m - 1, 0},
      {"mid", 300, 100, 30, 13, 0.5 * (style.fade_start_m + style.fade_end_m), 0},
      {"far", 500, 100, 30, 13, style.fade_end_m + 1, 0}};
  const auto f = viewer::LayoutLabels(fade, 640, 480);
  ASSERT_EQ(f.size(), 2u);
  EXPECT_FLOAT_EQ(f[0].alpha, 1.0f);
  EXPECT_NEAR(f[1].alpha, 0.5f, 1e-6);
}

// --- the viewer in-process -------------------------------------------------------------------

constexpr int kW = 640, kH = 480;
constexpr int kTol = 12;

class ViewerApp : public ::testing::Test {
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
  static ViewerOptions Options(std::uint32_t domain) {
    ViewerOptions o;
    o.domain = domain;
    o.hidden = true;
    o.fps = 0;
    o.samples = 0;
    o.width = kW;
    o.height = kH;
    o.wait_s = 60;
    return o;
  }
  static bool FramesUntil(Viewer& v, const std::function<void()>& publish,
                          const std::function<bool()>& done) {
    const auto deadline = base::MonotonicNow() + base::Seconds(60);
    while (base::MonotonicNow() < deadline) {
      if (publish) publish();
      if (!v.Frame()) return false;
      if (done()) return true;
    }
    return false;
  }
  static Image Show(Viewer& v, TestPublisher& pub, const std::vector<pb::VehicleState>& states) {
    const bool shown = FramesUntil(
        v,
        [&] {
          for (const auto& s : states) pub.State(s);
        },
        [&] {
          for (const auto& s : states) {
            const viewer::VehicleView* view = v.vehicle(s.vehicle_id());
            if (view == nullptr || view->step != s.step()) return false;
          }
          return true;
        });
    EXPECT_TRUE(shown) << "the viewer did not draw the published states within 60 s";
    return Keep(v.Screenshot());
  }
  static Image Keep(Image img) {
    static int n = 0;
    if (const char* dir = std::getenv("VDYN_VIEWER_TEST_PNGS")) {
      const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
      viewer::WritePng(std::string(dir) + "/" + info->test_suite_name() + "." + info->name() + "-" +
                           std::to_string(++n) + ".png",
                       img);
    }
    return img;
  }
  static void Key(SDL_Keycode k) {
    SDL_Event e{};
    e.type = SDL_KEYDOWN;
    e.key.keysym.sym = k;
    SDL_PushEvent(&e);
    e.type = SDL_KEYUP;
    SDL_PushEvent(&e);
  }
  static bool HudHas(const Viewer& v, const std::string& text) {
    for (const std::string& l : v.hud_text()) {
      if (l.find(text) != std::string::npos) return true;
    }
    return false;
  }
  static std::string Hud(const Viewer& v) {
    std::string s;
    for (const std::string& l : v.hud_text()) s += l + "\n";
    return s;
  }
  static Xvfb* xvfb_;
};
Xvfb* ViewerApp::xvfb_ = nullptr;

// Before any server is heard the HUD says so, WAITING in amber (it read "LIVE server ''  world
// '(waiting)'"); once one is, it names it.
TEST_F(ViewerApp, TheHudSaysWhenNoServerHasBeenHeardYet) {
  const std::uint32_t domain = FreshDomain();
  ViewerOptions o = Options(domain);
  ASSERT_TRUE(o.hud);
  Viewer v(o);
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(v.Frame());
  EXPECT_TRUE(HudHas(v, "WAITING  no server yet on domain " + std::to_string(domain))) << Hud(v);
  EXPECT_FALSE(HudHas(v, "server ''")) << Hud(v);
  EXPECT_FALSE(HudHas(v, "LIVE")) << Hud(v);
  EXPECT_FALSE(HudHas(v, "(waiting)")) << Hud(v);
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  Show(v, pub, {MakeState(TestVehicle{})});
  EXPECT_TRUE(HudHas(v, "LIVE  server 'test'")) << Hud(v);
}

TEST_F(ViewerApp, TheDriverCameraShowsTheRoadAheadNotItsOwnArrowsAndTyres) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  ViewerOptions o = Options(domain);
  o.hud = false;
  o.camera.mode = CameraMode::kDriver;
  Viewer v(o);
  // Large forces at every wheel: 4 kN springs (2 m arrows), drive and side forces.
  TestVehicle t;
  for (auto& w : t.wheels) w = {4000, 2000, 0, 1500};
  const Image img = Show(v, pub, {MakeState(t)});
  // The road ahead through the windscreen, between the horizon and the bonnet (the cockpit's
  // dashboard and wheel fill the view below it; cockpit tests below): none of the arrows' or the
  // vehicle's colours, and asphalt mostly (grey: textured, its pixels are classified; its lane
  // marking is white). (Without the cockpit this was the lower middle of the view, where the
  // front tyres and their arrows had been.)
  const Rect lower{kW * 42 / 100, kH * 45 / 100, kW * 58 / 100, kH / 2};
  for (int k = 0; k < viewer::kForceKinds; ++k) {
    const viewer::Rgb8 c = viewer::ForceColour(static_cast<viewer::ForceKind>(k));
    EXPECT_EQ(FindColour(img, c.r, c.g, c.b, kTol, lower).count, 0)
        << viewer::ForceLabel(static_cast<viewer::ForceKind>(k)) << " in the driver's view";
  }
  const viewer::Rgb8 own = viewer::VehicleColour(1);
  EXPECT_EQ(FindColour(img, own.r, own.g, own.b, kTol, lower).count, 0);
  const RegionStats road = Classify(img, lower);
  EXPECT_GT(road.asphalt, road.pixels * 8 / 10) << "the road ahead is not what the driver sees";
  EXPECT_EQ(road.grass, 0);
  // Another vehicle 15 m ahead is drawn, arrows and all.
  TestVehicle ahead = t;
  ahead.id = 2;
  ahead.x = 15;
  const Image with = Show(v, pub, {MakeState(t), MakeState(ahead)});
  const viewer::Rgb8 g = viewer::ForceColour(viewer::ForceKind::kSpring);
  EXPECT_GT(FindColour(with, g.r, g.g, g.b, kTol).count, 50) << "the car ahead's springs";
}

// Switching away from the driver camera: every frame is drawn whole from one camera - the one
// its HUD names - and none from inside the body (issue 35: one frame from the driver's seat
// with the body drawn, a dark void with two green spring arrows, while the HUD said "driver").
TEST_F(ViewerApp, SwitchingFromTheDriverCameraNeverDrawsAFrameFromInsideTheBody) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  ViewerOptions o = Options(domain);
  o.camera.mode = CameraMode::kDriver;
  o.camera.cockpit = false;  // nothing of the own car from its seat (the cockpit: tests below)
  Viewer v(o);
  TestVehicle t;
  for (auto& w : t.wheels) w = {4000, 0, 0, 0};  // 2 m spring arrows
  Show(v, pub, {MakeState(t)});
  const viewer::Rgb8 own = viewer::VehicleColour(1);
  const viewer::Rgb8 spring = viewer::ForceColour(viewer::ForceKind::kSpring);
  // Below the HUD's panels: the road from the seat, the car's rear from behind.
  const Rect middle{kW / 4, kH / 2, kW * 3 / 4, kH};
  for (SDL_Keycode key : {SDLK_1, SDLK_2, SDLK_3, SDLK_2, SDLK_5, SDLK_2, SDLK_6}) {
    const bool to_driver = key == SDLK_2;
    Key(key);
    for (int frame = 0; frame < 3; ++frame) {
      ASSERT_TRUE(v.Frame());
      const Image img = Keep(v.Screenshot());
      int dark = 0;
      for (int y = middle.y0; y < middle.y1; ++y) {
        for (int x = middle.x0; x < middle.x1; ++x) {
          const std::uint8_t* p = &img.rgba[(static_cast<std::size_t>(y) * img.width + x) * 4];
          dark += p[0] < 40 && p[1] < 40 && p[2] < 40 ? 1 : 0;
        }
      }
      const int pixels = (middle.x1 - middle.x0) * (middle.y1 - middle.y0);
      SCOPED_TRACE("key " + std::string(SDL_GetKeyName(key)) + ", frame " + std::to_string(frame) +
                   "\n" + Hud(v));
      EXPECT_LT(dark, pixels / 4) << "a dark void: the inside of the body";
      const bool hud_driver = HudHas(v, "camera driver");
      const int body = FindColour(img, own.r, own.g, own.b, kTol, middle).count;
      const int arrows = FindColour(img, spring.r, spring.g, spring.b, kTol, middle).count;
      if (hud_driver) {
        // From the seat: nothing of the own car's body paint or arrows in view.
        EXPECT_EQ(arrows, 0) << "the own car's spring arrows from the driver's seat";
        EXPECT_EQ(body, 0) << "the own car's body from the driver's seat";
      } else {
        EXPECT_GT(arrows, 0) << "the car's spring arrows from outside";
      }
      // The new camera within a frame or two (the HUD takes the key at the frame it arrives).
      if (frame == 2) {
        EXPECT_EQ(hud_driver, to_driver);
      }
    }
  }
}

// --- the car's lamps ------------------------------------------------------------------------

// Pixels of a lit lamp in the view: saturated (a channel at 250 or more) in the lamp's hue.
struct Lamps {
  int red_left = 0, red_right = 0;  // brake-light red (R >= 250, G and B <= 110), each half
  int white = 0;                    // reversing-light white (every channel >= 250)
  std::vector<std::size_t> red_at;  // where the red ones are (pixel indices)
};
Lamps FindLamps(const Image& img, Rect region) {
  Lamps l;
  for (int y = region.y0; y < std::min(region.y1, img.height); ++y) {
    for (int x = region.x0; x < std::min(region.x1, img.width); ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * img.width + x;
      const std::uint8_t* p = &img.rgba[i * 4];
      if (p[0] >= 250 && p[1] <= 110 && p[2] <= 110) {
        (x < img.width / 2 ? l.red_left : l.red_right)++;
        l.red_at.push_back(i);
      }
      if (p[0] >= 250 && p[1] >= 250 && p[2] >= 250) ++l.white;
    }
  }
  return l;
}

// The mean luma (sRGB, 0..255) of some pixels.
double MeanLuma(const Image& img, const std::vector<std::size_t>& at) {
  double sum = 0;
  for (std::size_t i : at) {
    const std::uint8_t* p = &img.rgba[i * 4];
    sum += 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
  }
  return at.empty() ? 0.0 : sum / static_cast<double>(at.size());
}

// One body colour per vehicle from a fixed palette of eight: vehicles 1 to 8 each their own, at
// least 40 levels apart in some channel from each other and 60 from every force arrow's colour
// (the arrows stay readable on any car), vehicle 9 as vehicle 1 again.
TEST(VehicleColours, EightVehiclesEightColoursApartFromEachOtherAndTheArrows) {
  auto distance = [](viewer::Rgb8 a, viewer::Rgb8 b) {
    return std::max({std::abs(a.r - b.r), std::abs(a.g - b.g), std::abs(a.b - b.b)});
  };
  for (std::uint32_t i = 1; i <= 8; ++i) {
    for (std::uint32_t j = i + 1; j <= 8; ++j) {
      EXPECT_GE(distance(viewer::VehicleColour(i), viewer::VehicleColour(j)), 40)
          << "vehicles " << i << " and " << j;
    }
    for (int k = 0; k < viewer::kForceKinds; ++k) {
      EXPECT_GE(distance(viewer::VehicleColour(i),
                         viewer::ForceColour(static_cast<viewer::ForceKind>(k))),
                60)
          << "vehicle " << i << " and " << viewer::ForceLabel(static_cast<viewer::ForceKind>(k));
    }
  }
  const viewer::Rgb8 first = viewer::VehicleColour(1), ninth = viewer::VehicleColour(9);
  EXPECT_EQ(distance(first, ninth), 0);
}

TEST_F(ViewerApp, TheBrakeLightsLightWhileBrakingAndTheReversingLightsInReverse) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  // At both qualities (low: no glossy shading, as on a software renderer).
  for (viewer::Quality q : {viewer::Quality::kHigh, viewer::Quality::kLow}) {
    SCOPED_TRACE(std::string(viewer::QualityName(q)));
    ViewerOptions o = Options(domain);
    o.hud = false;
    o.quality = q;
    o.camera.mode = CameraMode::kChase;  // behind the car: its rear in the middle of the view
    o.delay_ns = 0;
    Viewer v(o);
    TestVehicle t;
    t.step = q == viewer::Quality::kHigh ? 1 : 1000;
    for (auto& w : t.wheels) w.fp = 0;                            // no arrows over the rear
    const Rect rear{kW * 3 / 8, kH / 2, kW * 5 / 8, kH * 3 / 4};  // the car's rear
    auto state = [&](double brake, double brake_torque, int gear) {
      ++t.step;
      pb::VehicleState s = MakeState(t);
      s.mutable_control()->set_brake(brake);
      for (auto& w : *s.mutable_wheels()) w.set_brake_torque(brake_torque);
      s.mutable_drivetrain()->set_gear(gear);
      return s;
    };
    const Image off = Show(v, pub, {state(0.0, 0.0, 1)});
    const Image braking = Show(v, pub, {state(0.6, 0.0, 1)});
    const Image torque = Show(v, pub, {state(0.0, 400.0, 1)});  // the full model's brake torque
    const Image reverse = Show(v, pub, {state(0.0, 0.0, -1)});
    const Lamps l_off = FindLamps(off, rear), l_brake = FindLamps(braking, rear);
    // The paper model (no gearbox: gear 0) driven backwards at 2 m/s.
    t.speed = -2;
    for (auto& w : t.wheels) w.fh = -300;
    const Image backwards = Show(v, pub, {state(0.0, 0.0, 0)});
    const Lamps l_torque = FindLamps(torque, rear), l_reverse = FindLamps(reverse, rear);
    EXPECT_GT(FindLamps(backwards, rear).white, 20) << "driven backwards";
    // Both brake lights lit while braking (by the input or by the torque), neither otherwise.
    EXPECT_GT(l_brake.red_left, 20);
    EXPECT_GT(l_brake.red_right, 20);
    EXPECT_GT(l_torque.red_left, 20);
    EXPECT_GT(l_torque.red_right, 20);
    EXPECT_LT(l_off.red_left + l_off.red_right, 5) << "the brake lights are lit without braking";
    EXPECT_LT(l_reverse.red_left + l_reverse.red_right, 5);
    // Where they are, the lamps are clearly brighter braking than not.
    const double lit = MeanLuma(braking, l_brake.red_at), unlit = MeanLuma(off, l_brake.red_at);
    EXPECT_GT(lit, 1.5 * unlit) << "lit " << lit << ", unlit " << unlit;
    // The reversing lights in reverse gear only.
    EXPECT_GT(l_reverse.white, 20);
    EXPECT_LT(l_off.white, 5);
    EXPECT_LT(l_brake.white, 5);
  }
}

// --- the cockpit ---------------------------------------------------------------------------

// A full-model state of vehicle 1 at `kmh` (along its heading), its hand wheel at `wheel_rad`,
// its engine at `rpm` in `gear`.
pb::VehicleState Cockpit(std::uint64_t step, double kmh, double wheel_rad, double rpm, int gear) {
  TestVehicle t;
  for (auto& w : t.wheels) w.fp = 0;
  t.step = step;
  t.speed = kmh / 3.6;
  pb::VehicleState s = MakeState(t);
  s.set_model(pb::VEHICLE_MODEL_FULL);
  s.mutable_steering()->set_hand_wheel_angle(wheel_rad);
  s.mutable_drivetrain()->set_engine_rpm(rpm);
  s.mutable_drivetrain()->set_gear(gear);
  return s;
}

// Pixels of one colour (within 10 per channel) and those of an orange hue (the wheel's lit top
// mark), in a region.
Blob Orange(const Image& img, Rect r) {
  Blob b;
  for (int y = r.y0; y < std::min(r.y1, img.height); ++y) {
    for (int x = r.x0; x < std::min(r.x1, img.width); ++x) {
      const std::uint8_t* p = &img.rgba[(static_cast<std::size_t>(y) * img.width + x) * 4];
      if (p[0] > 110 && p[0] > 1.3 * p[1] && p[1] > 1.5 * p[2] && p[1] > 30) {
        b.cx += x;
        b.cy += y;
        ++b.count;
      }
    }
  }
  if (b.count > 0) {
    b.cx /= b.count;
    b.cy /= b.count;
  }
  return b;
}

int ChangedPixels(const Image& a, const Image& b, Rect r) {
  int n = 0;
  for (int y = r.y0; y < r.y1; ++y) {
    for (int x = r.x0; x < r.x1; ++x) {
      const std::size_t i = (static_cast<std::size_t>(y) * a.width + x) * 4;
      for (int c = 0; c < 3; ++c) {
        if (std::abs(a.rgba[i + c] - b.rgba[i + c]) > 30) {
          ++n;
          break;
        }
      }
    }
  }
  return n;
}

class CockpitTest : public ViewerApp {
 protected:
  static ViewerOptions DriverOptions(std::uint32_t domain) {
    ViewerOptions o = Options(domain);
    o.hud = false;
    o.camera.mode = CameraMode::kDriver;
    o.delay_ns = 0;
    return o;
  }
};

// The steering wheel turns with the published hand-wheel angle: its lower half of the view
// changes between 0 and 90 deg (and not between two frames at the same angle), and its top mark
// goes to the driver's left for a left turn (positive), to the right for a right one.
TEST_F(CockpitTest, TheSteeringWheelTurnsWithTheHandWheelAngle) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  Viewer v(DriverOptions(domain));
  const Image straight = Show(v, pub, {Cockpit(1, 0, 0, 900, 1)});
  const Image left = Show(v, pub, {Cockpit(2, 0, viewer::Rad(90), 900, 1)});
  const Image right = Show(v, pub, {Cockpit(3, 0, viewer::Rad(-90), 900, 1)});
  const Image again = Show(v, pub, {Cockpit(4, 0, 0, 900, 1)});
  const Rect wheel{0, kH * 55 / 100, kW, kH};
  const int pixels = wheel.x1 * (wheel.y1 - wheel.y0);
  EXPECT_GT(ChangedPixels(straight, left, wheel), pixels / 100) << "the wheel did not turn";
  EXPECT_LT(ChangedPixels(straight, again, wheel), pixels / 1000) << "not the same at 0 deg";
  const Blob top = Orange(straight, wheel), l = Orange(left, wheel), r = Orange(right, wheel);
  ASSERT_GT(top.count, 20);
  ASSERT_GT(l.count, 10);
  ASSERT_GT(r.count, 10);
  EXPECT_NEAR(top.cx, kW / 2, kW / 20) << "the mark is at the wheel's top, straight ahead";
  EXPECT_LT(l.cx, top.cx - kW / 8) << "turned left: the mark on the driver's left";
  EXPECT_GT(r.cx, top.cx + kW / 8) << "turned right: the mark on the driver's right";
  EXPECT_GT(l.cy, top.cy + 20) << "a quarter turn: the mark down at the wheel's side";
}

// A car close ahead: the lower parts of its spring arrows are behind the dashboard. They are
// hidden there, not drawn as the faint ghost that marks an arrow the terrain hides (green over
// the dashboard, the dials and the wheel).
TEST_F(CockpitTest, AnArrowTheDashboardHidesLeavesNoGhostOnIt) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2, {1, 2})));
  Viewer v(DriverOptions(domain));
  TestVehicle own, ahead;
  for (auto& w : own.wheels) w.fp = 0;
  ahead.id = 2;
  ahead.x = 5;  // its rear wheels 3.85 m ahead of the eyes, their contact 16 deg below them
  for (auto& w : ahead.wheels) w.fp = 4000;  // 2 m arrows up
  const Image img = Show(v, pub, {MakeState(own), MakeState(ahead)});
  const viewer::Rgb8 g = viewer::ForceColour(viewer::ForceKind::kSpring);
  ASSERT_GT(FindColour(img, g.r, g.g, g.b, kTol).count, 50) << "the arrows over the windscreen";
  int greenish = 0;
  // Below the dashboard's top edge, right of the side window.
  for (int y = kH * 62 / 100; y < kH; ++y) {
    for (int x = kW / 5; x < kW; ++x) {
      const std::uint8_t* p = &img.rgba[(static_cast<std::size_t>(y) * kW + x) * 4];
      greenish += p[1] > p[0] + 30 && p[1] > p[2] + 30 ? 1 : 0;
    }
  }
  EXPECT_EQ(greenish, 0) << "an arrow's ghost over the dashboard";
}

// The speedometer's needle, measured from the pixels: the angle from its hub to the needle's
// pixels on the screen, clockwise from up, is the dial's: -135 deg at 0 km/h to +135 deg at
// 260 km/h, within 4 deg. The tachometer's needle (the right dial) turns with the engine speed;
// the gear shows between them.
TEST_F(CockpitTest, TheDialsNeedlesShowTheSpeedAndTheEngineSpeed) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  // At both qualities (low: as on a software renderer).
  for (viewer::Quality q : {viewer::Quality::kHigh, viewer::Quality::kLow}) {
    SCOPED_TRACE(std::string(viewer::QualityName(q)));
    ViewerOptions o = DriverOptions(domain);
    o.quality = q;
    Viewer v(o);
    auto needle_deg = [](const Image& img, Rect dial) {
      const Blob needle = FindColour(img, 255, 80, 0, 10, dial);
      const Blob hub = FindColour(img, 0, 160, 230, 10, dial);
      EXPECT_GT(needle.count, 15);
      EXPECT_GT(hub.count, 4);
      return viewer::Deg(std::atan2(needle.cx - hub.cx, -(needle.cy - hub.cy)));
    };
    const Rect speedo{0, kH / 2, kW / 2, kH}, tacho{kW / 2, kH / 2, kW, kH};
    std::uint64_t step = q == viewer::Quality::kHigh ? 1 : 1000;
    double tacho_deg[2] = {0, 0};
    int k = 0;
    for (double kmh : {30.0, 100.0, 170.0}) {
      const double rpm = kmh < 50 ? 2000 : 5000;
      const Image img = Show(v, pub, {Cockpit(step++, kmh, 0, rpm, 3)});
      const double expected = -135 + 270 * kmh / 260;
      EXPECT_NEAR(needle_deg(img, speedo), expected, 4) << kmh << " km/h";
      if (k < 2) tacho_deg[k++] = needle_deg(img, tacho);
    }
    EXPECT_GT(tacho_deg[1] - tacho_deg[0], 60) << "2000 -> 5000 rpm: the tachometer's needle";
    // The gear between the dials, on seven segments: 3 lights five of them, 1 two.
    auto lit_segments = [&](int gear) {
      const Image img = Show(v, pub, {Cockpit(step++, 50, 0, 2000, gear)});
      const Rect digit{kW * 46 / 100, kH / 2, kW * 54 / 100, kH};
      return FindColour(img, 250, 250, 250, 6, digit).count;
    };
    const int first = lit_segments(1), third = lit_segments(3);
    EXPECT_GT(first, 5) << "no gear shown";
    EXPECT_GT(third, 2 * first) << "gear 3 (" << third << " px) against gear 1 (" << first << ")";
  }
}

// Where a mirror's glass is on the last frame's screen (its corners projected, a few pixels in
// from its edges), and its centre's column.
struct ScreenRect {
  Rect r;
  double centre_x = 0;
};
ScreenRect MirrorOnScreen(Viewer& v, int mirror, int width, int height) {
  const viewer::VehicleView* own = v.vehicle(1);
  EXPECT_NE(own, nullptr);
  if (own == nullptr) return {};
  const viewer::Mirror m = viewer::MirrorsFor(
      own->geometry, viewer::CabinFor(own->geometry).eyes_B)[static_cast<std::size_t>(mirror)];
  const viewer::CameraView& cam = v.last_camera();
  double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
  for (double sx : {-1.0, 1.0}) {
    for (double sy : {-1.0, 1.0}) {
      const Vec3 c_B = m.centre_B + m.right_B * (sx * m.half_width) + m.up_B * (sy * m.half_height);
      double w = 0;
      const Vec3 ndc = (cam.proj * cam.view).TransformPoint(own->pose_WB * c_B, &w);
      EXPECT_GT(w, 0) << "mirror " << mirror << " behind the camera";
      const double x = (ndc.x / w * 0.5 + 0.5) * width, y = (0.5 - 0.5 * ndc.y / w) * height;
      x0 = std::min(x0, x);
      x1 = std::max(x1, x);
      y0 = std::min(y0, y);
      y1 = std::max(y1, y);
    }
  }
  ScreenRect s;
  s.r = {std::max(0, static_cast<int>(x0) + 3), std::max(0, static_cast<int>(y0) + 3),
         std::min(width, static_cast<int>(x1) - 3), std::min(height, static_cast<int>(y1) - 3)};
  s.centre_x = 0.5 * (x0 + x1);
  EXPECT_GT(s.r.x1 - s.r.x0, 20) << "mirror " << mirror << " not on the screen";
  EXPECT_GT(s.r.y1 - s.r.y0, 5) << "mirror " << mirror << " not on the screen";
  return s;
}

// The pixels of a region that differ between two images (over 30 levels in a channel), and
// their centroid.
Blob Changed(const Image& a, const Image& b, Rect r) {
  Blob d;
  for (int y = r.y0; y < r.y1; ++y) {
    for (int x = r.x0; x < r.x1; ++x) {
      const std::size_t i = (static_cast<std::size_t>(y) * a.width + x) * 4;
      for (int c = 0; c < 3; ++c) {
        if (std::abs(a.rgba[i + c] - b.rgba[i + c]) > 30) {
          d.cx += x;
          d.cy += y;
          ++d.count;
          break;
        }
      }
    }
  }
  if (d.count > 0) {
    d.cx /= d.count;
    d.cy /= d.count;
  }
  return d;
}

// The mirrors show the world behind. A second car 12 m behind (1.8 m to the left, then to the
// right) shows in the rear-view mirror and not when it is far away. An interior mirror reverses
// front and back, not left and right: a car behind on the left is on the mirror's left as the
// driver sees it (a camera looking back would show it on its right). Each side mirror shows a
// car 10 m along its line of sight, the other side mirror does not. A wide view (3:1, 90 deg
// high) sees all three mirrors. At high and low quality.
TEST_F(CockpitTest, TheMirrorsShowWhatIsBehindReflectedAsAMirrorDoes) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2, {1, 2})));
  std::uint64_t step = 1;
  // At both qualities (low: smaller images, the mirrors drawn in turns, one a frame).
  for (viewer::Quality q : {viewer::Quality::kHigh, viewer::Quality::kLow}) {
    SCOPED_TRACE(std::string(viewer::QualityName(q)));
    ViewerOptions o = DriverOptions(domain);
    o.quality = q;
    constexpr int kWide = 1200, kLow = 400;
    o.width = kWide;
    o.height = kLow;
    o.camera.fovy = viewer::Rad(90);
    Viewer v(o);
    TestVehicle own, other;
    for (auto& w : own.wheels) w.fp = 0;
    other.id = 2;
    for (auto& w : other.wheels) w.fp = 0;
    auto show_other_at = [&](double x, double y) {
      own.step = other.step = step++;
      other.x = x;
      other.y = y;
      Show(v, pub, {MakeState(own), MakeState(other)});
      for (int i = 0; i < 3; ++i) EXPECT_TRUE(v.Frame());  // every mirror's turn at low
      return Keep(v.Screenshot());
    };
    const Image away = show_other_at(-12, 150);
    const ScreenRect rear = MirrorOnScreen(v, viewer::kRearViewMirror, kWide, kLow);
    const int rear_px = (rear.r.x1 - rear.r.x0) * (rear.r.y1 - rear.r.y0);
    const Image behind_left = show_other_at(-12, 1.8);
    const Image behind_right = show_other_at(-12, -1.8);
    const Image away_again = show_other_at(-12, 150);
    const Blob left = Changed(away, behind_left, rear.r),
               right = Changed(away, behind_right, rear.r);
    EXPECT_GT(left.count, rear_px / 20) << "the car behind on the left is not in the mirror";
    EXPECT_GT(right.count, rear_px / 20) << "the car behind on the right is not in the mirror";
    EXPECT_LT(Changed(away, away_again, rear.r).count, rear_px / 200) << "moved away: still seen";
    EXPECT_LT(left.cx, rear.centre_x) << "behind on the left: on the mirror's left";
    EXPECT_GT(right.cx, rear.centre_x) << "behind on the right: on the mirror's right";

    // The side mirrors: a car 10 m along each one's line of sight.
    const viewer::VehicleGeometry& g = v.vehicle(1)->geometry;
    const auto mirrors = viewer::MirrorsFor(g, viewer::CabinFor(g).eyes_B);
    const ScreenRect side[2] = {MirrorOnScreen(v, viewer::kLeftMirror, kWide, kLow),
                                MirrorOnScreen(v, viewer::kRightMirror, kWide, kLow)};
    for (int k = 0; k < 2; ++k) {
      const viewer::Mirror& m =
          mirrors[static_cast<std::size_t>(k == 0 ? viewer::kLeftMirror : viewer::kRightMirror)];
      const Vec3 p = m.centre_B + m.look_B * 10.0;  // (own car at the origin, heading along X)
      const Image seen = show_other_at(p.x, p.y);
      const int px = (side[k].r.x1 - side[k].r.x0) * (side[k].r.y1 - side[k].r.y0);
      const int other_px =
          (side[1 - k].r.x1 - side[1 - k].r.x0) * (side[1 - k].r.y1 - side[1 - k].r.y0);
      EXPECT_GT(Changed(away, seen, side[k].r).count, px / 10)
          << (k == 0 ? "left" : "right") << " mirror: the car along its line of sight";
      EXPECT_LT(Changed(away, seen, side[1 - k].r).count, other_px / 200)
          << (k == 0 ? "right" : "left") << " mirror shows the car behind on the other side";
    }
  }
}

// --- the driver's seat, sized from the vehicle -------------------------------------------------

// A large vehicle (an SUV or van: 5.5 m long, 2 m wide, 0.45 m wheels on a 3.3 m wheelbase)
// beside the tests' 4.7 m saloon (TestCar): its geometry in the test world as vehicle 1, and its
// state standing on the road (T at its own height: the mount's depth, the spring at 70 % of its
// free length, the radius).
struct BigCar {
  static constexpr double kB = 1.55, kC = 1.75, kBl = 0.86, kZ = 0.0;
  static constexpr double kRadius = 0.45, kFree = 0.40;
  static constexpr double kFront = 2.6, kRear = 2.9, kHalfWidth = 1.0;
  static constexpr double kHeight = TestCar::kGround - kZ + 0.7 * kFree + kRadius;
};
pb::WorldDescription BigCarWorld() {
  pb::WorldDescription w = MakeWorld("test", kPi / 2);
  pb::VehicleGeometry* g = w.mutable_vehicles(0);
  for (int k = 0; k < 4; ++k) {
    pb::Vec3* a = g->mutable_mount_points_b(k);
    a->set_x(k < 2 ? BigCar::kB : -BigCar::kC);
    a->set_y(k % 2 == 0 ? BigCar::kBl : -BigCar::kBl);
    a->set_z(BigCar::kZ);
    g->set_wheel_radius(k, BigCar::kRadius);
    g->set_free_length(k, BigCar::kFree);
  }
  g->set_body_front(BigCar::kFront);
  g->set_body_rear(BigCar::kRear);
  g->set_body_half_width(BigCar::kHalfWidth);
  return w;
}
pb::VehicleState BigCarState(std::uint64_t step) {
  TestVehicle t;
  for (auto& w : t.wheels) w.fp = 0;
  t.step = step;
  pb::VehicleState s = MakeState(t);
  s.mutable_p_wt_w()->set_z(BigCar::kHeight);
  for (int k = 0; k < 4; ++k) {
    pb::WheelState* ws = s.mutable_wheels(k);
    ws->mutable_p_a_w()->set_x(k < 2 ? BigCar::kB : -BigCar::kC);
    ws->mutable_p_a_w()->set_y(k % 2 == 0 ? BigCar::kBl : -BigCar::kBl);
    ws->mutable_p_a_w()->set_z(BigCar::kHeight + BigCar::kZ);
    ws->set_ls(0.7 * BigCar::kFree);
  }
  return s;
}

// The driver's eyes lie in each vehicle's own cabin (left-hand drive): left of the centre line
// inside the body, behind the windscreen and ahead of the roof's rear edge, over the bonnet and
// the dashboard (above the belt line at the windscreen's base, or the road ahead is hidden),
// under the roof with a hand's headroom, well above the floor. A fixed seat (the one every
// vehicle had: {-0.35, 0.37, 0.55}) lies under the large vehicle's belt line: checked.
TEST(DriversSeat, TheEyesLieInEachVehiclesOwnCabin) {
  const pb::WorldDescription saloon_world = MakeWorld("test", kPi / 2), big_world = BigCarWorld();
  const viewer::VehicleGeometry saloon = viewer::GeometryFor(1, &saloon_world, nullptr);
  const viewer::VehicleGeometry big = viewer::GeometryFor(1, &big_world, nullptr);
  ASSERT_EQ(big.source, viewer::VehicleGeometry::Source::kWorld);
  ASSERT_NEAR(big.radius[0], BigCar::kRadius, 1e-9);
  std::array<Vec3, 2> eyes{};
  for (int i = 0; i < 2; ++i) {
    SCOPED_TRACE(i == 0 ? "the saloon" : "the large vehicle");
    const viewer::VehicleGeometry& g = i == 0 ? saloon : big;
    const viewer::Cabin cab = viewer::CabinFor(g);
    const Vec3 e = cab.eyes_B;
    eyes[static_cast<std::size_t>(i)] = e;
    EXPECT_GT(e.y, 0.2 * g.half_width) << "left-hand drive: the driver sits left of the centre";
    EXPECT_LT(e.y, 0.7 * g.half_width);
    // The windscreen runs from the cowl (x_cowl, z_belt_cowl) to the roof's front edge.
    const double u = (e.z - cab.z_belt_cowl) / (cab.z_roof_front - cab.z_belt_cowl);
    const double x_glass = cab.x_cowl + u * (cab.x_roof_front - cab.x_cowl);
    EXPECT_LT(e.x, x_glass - 0.3) << "behind the windscreen";
    EXPECT_GT(e.x, cab.x_roof_rear) << "under the roof, ahead of its rear edge";
    EXPECT_GT(e.z, cab.z_belt_cowl + 0.05) << "over the bonnet and the dashboard";
    EXPECT_LT(e.z, cab.z_roof_front - 0.1) << "a hand's headroom under the roof";
    EXPECT_GT(e.z, cab.H(0.30) + 0.5) << "well above the floor";
  }
  // The large vehicle's eyes sit higher, and further from its nose.
  EXPECT_GT(eyes[1].z, eyes[0].z + 0.2);
  EXPECT_GT(BigCar::kFront - eyes[1].x, TestCar::kFront - eyes[0].x);
}

// From the driver's seat of each vehicle the road ahead fills the middle of the view above the
// dashboard, the bonnet shows between them (the eyes are over the cowl), and the steering
// wheel's top mark is straight ahead below (the checks of
// TheDriverCameraShowsTheRoadAheadNotItsOwnArrowsAndTyres and TheSteeringWheelTurnsWith...).
// From the fixed seat the large vehicle's dashboard hides its bonnet: checked.
TEST_F(CockpitTest, FromEachVehiclesSeatTheRoadAheadAndTheSteeringWheelShow) {
  for (int i = 0; i < 2; ++i) {
    SCOPED_TRACE(i == 0 ? "the saloon" : "the large vehicle");
    const std::uint32_t domain = FreshDomain();
    TestPublisher pub(domain);
    ASSERT_TRUE(pub.World(i == 0 ? MakeWorld("test", kPi / 2) : BigCarWorld()));
    Viewer v(DriverOptions(domain));
    const Image img = Show(v, pub, {i == 0 ? Cockpit(1, 0, 0, 900, 1) : BigCarState(1)});
    ASSERT_NE(v.vehicle(1), nullptr);
    ASSERT_NEAR(v.vehicle(1)->geometry.half_width,
                i == 0 ? TestCar::kHalfWidth : BigCar::kHalfWidth, 1e-9);
    const Rect ahead{kW * 42 / 100, kH * 45 / 100, kW * 58 / 100, kH / 2};
    const RegionStats road = Classify(img, ahead);
    EXPECT_GT(road.asphalt, road.pixels * 8 / 10) << "the road ahead is not what the driver sees";
    // The bonnet: vehicle 1's pale blue paint, lit, below the horizon in the middle.
    int bonnet = 0;
    for (int y = kH * 45 / 100; y < kH * 65 / 100; ++y) {
      for (int x = kW * 30 / 100; x < kW * 70 / 100; ++x) {
        const std::uint8_t* p = &img.rgba[(static_cast<std::size_t>(y) * kW + x) * 4];
        bonnet += p[2] > 150 && p[1] > 140 && p[2] > p[0] + 25;
      }
    }
    EXPECT_GT(bonnet, 1000) << "no bonnet over the dashboard";
    const Blob mark = Orange(img, {0, kH * 55 / 100, kW, kH});
    EXPECT_GT(mark.count, 20) << "no steering wheel";
    EXPECT_NEAR(mark.cx, kW / 2, kW / 20) << "the wheel's top straight ahead of the eyes";
  }
}

TEST_F(ViewerApp, TheForcesLegendStartsCollapsedAndLOpensIt) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  ViewerOptions o = Options(domain);
  o.camera.mode = CameraMode::kMap;
  Viewer v(o);
  TestVehicle t;
  for (auto& w : t.wheels) w.fp = 0;  // no arrows in the scene: their colours are the legend's
  Show(v, pub, {MakeState(t)});
  // (ImGui shows a new window from its second frame on.)
  for (int i = 0; i < 3; ++i) v.Frame();
  Image img = Keep(v.Screenshot());
  const Rect bottom_left{0, kH / 2, kW / 2, kH};
  auto swatches = [&](const Image& im) {
    int n = 0;
    for (int k = 0; k < viewer::kForceKinds; ++k) {
      const viewer::Rgb8 c = viewer::ForceColour(static_cast<viewer::ForceKind>(k));
      n += FindColour(im, c.r, c.g, c.b, 4, bottom_left).count > 100 ? 1 : 0;
    }
    return n;
  };
  EXPECT_EQ(swatches(img), 0) << "the legend is open at the start";
  // (An opened window takes a frame or two to size itself to what it holds.)
  auto frames_until = [&](int want) {
    for (int i = 0; i < 10; ++i) {
      v.Frame();
      img = Keep(v.Screenshot());
      if (swatches(img) == want) return true;
    }
    return false;
  };
  Key(SDLK_l);
  EXPECT_TRUE(frames_until(viewer::kForceKinds)) << "L did not open the legend";
  Key(SDLK_l);
  EXPECT_TRUE(frames_until(0)) << "L did not close it again";
}

// The parameters of vehicle 1 as a server publishes them (every field set).
pb::VehicleParams AllParams() {
  pb::VehicleParams p;
  const auto* d = p.GetDescriptor();
  const auto* r = p.GetReflection();
  for (int i = 0; i < d->field_count(); ++i) {
    const auto* f = d->field(i);
    switch (f->cpp_type()) {
      case google::protobuf::FieldDescriptor::CPPTYPE_DOUBLE:
        r->SetDouble(&p, f, 1.5);
        break;
      case google::protobuf::FieldDescriptor::CPPTYPE_UINT32:
        r->SetUInt32(&p, f, 5);
        break;
      case google::protobuf::FieldDescriptor::CPPTYPE_BOOL:
        r->SetBool(&p, f, true);
        break;
      case google::protobuf::FieldDescriptor::CPPTYPE_ENUM:
        r->SetEnumValue(&p, f, 1);
        break;
      case google::protobuf::FieldDescriptor::CPPTYPE_MESSAGE: {
        // A wheel: its numbers, and a Magic Formula tyre by its name and coefficients (what a
        // server sends for a wheel given a .tir file; never the file's name).
        auto* w = r->MutableMessage(&p, f);
        const auto* wd = w->GetDescriptor();
        for (int k = 0; k < wd->field_count(); ++k) {
          if (wd->field(k)->cpp_type() == google::protobuf::FieldDescriptor::CPPTYPE_DOUBLE)
            w->GetReflection()->SetDouble(w, wd->field(k), 0.3);
        }
        auto* mf = static_cast<pb::WheelParams*>(w)->mutable_magic_formula();
        mf->set_name("synthetic 205/55 R16");
        mf->set_fnomin(4000.0);
        break;
      }
      default:
        break;
    }
  }
  return p;
}

// xdotool on the private X server (real pointer and key events, as a person's): true when it
// ran; its output in `out`.
bool Xdo(const std::vector<std::string>& args, std::string* out = nullptr) {
  static int n = 0;
  const auto log = std::filesystem::temp_directory_path() /
                   ("vdyn-xdo-" + std::to_string(getpid()) + "-" + std::to_string(++n) + ".log");
  std::vector<std::string> argv = {"/usr/bin/xdotool"};
  argv.insert(argv.end(), args.begin(), args.end());
  Process p(argv, log);
  const auto code = p.Wait(std::chrono::seconds(30));
  if (out != nullptr) *out = p.Log();
  std::filesystem::remove(log);
  return code == 0;
}

// The viewer's window on the X server.
std::string WindowId() {
  std::string out;
  if (!Xdo({"search", "--name", "^vdyn-viewer$"}, &out)) return {};
  return out.substr(0, out.find('\n'));
}

class ParamsPanel : public ViewerApp {
 protected:
  // A viewer following vehicle 1 with its parameters, the panel open.
  void Open() {
    domain_ = FreshDomain();
    pub_ = std::make_unique<TestPublisher>(domain_);
    ASSERT_TRUE(pub_->World(MakeWorld("test", kPi / 2)));
    ASSERT_TRUE(pub_->Params(1, AllParams()));
    ViewerOptions o = Options(domain_);
    o.camera.mode = CameraMode::kMap;
    o.hidden = false;  // a window on the X server, for the pointer and the keys
    v_ = std::make_unique<Viewer>(o);
    window_ = WindowId();
    ASSERT_FALSE(window_.empty()) << "no vdyn-viewer window on the X server";
    Show(*v_, *pub_, {MakeState(TestVehicle{})});
    Key(SDLK_p);
    ASSERT_TRUE(FramesUntil(
        *v_, [&] { pub_->State(MakeState(TestVehicle{})); },
        [&] { return v_->params_editor().drawn().count("mass") > 0; }))
        << "the parameters panel did not show the fields";
  }
  // A click at a point of the window.
  void Click(float x, float y) {
    ASSERT_TRUE(Xdo({"mousemove", "--window", window_, std::to_string(static_cast<int>(x)),
                     std::to_string(static_cast<int>(y)), "click", "1"}));
  }
  // Keys typed into the window.
  void Type(const std::string& text) {
    ASSERT_TRUE(Xdo({"type", "--window", window_, "--delay", "0", text}));
  }
  void Press(const std::string& key) { ASSERT_TRUE(Xdo({"key", "--window", window_, key})); }
  std::uint32_t domain_ = 0;
  std::unique_ptr<TestPublisher> pub_;
  std::unique_ptr<Viewer> v_;
  std::string window_;
};

TEST_F(ParamsPanel, EveryFieldIsNamedInWordsWithItsUnitFromTheOneTable) {
  Open();
  const auto& drawn = v_->params_editor().drawn();
  const auto* d = pb::VehicleParams::descriptor();
  for (int i = 0; i < d->field_count(); ++i) {
    const std::string path = d->field(i)->name();
    SCOPED_TRACE(path);
    // Tyre files' names travel only to the server (it sends their coefficients): not shown.
    if (path.starts_with("tire_file")) continue;
    const std::string_view words = limits::ParamWords(path);
    ASSERT_FALSE(words.empty()) << "the table does not name " << path;
    ASSERT_EQ(drawn.count(path), 1u) << "not in the panel";
    EXPECT_EQ(drawn.at(path).label, words);
    EXPECT_NE(drawn.at(path).label, path);
  }
  // The fields of a wheel, once its group is opened.
  const auto lf = drawn.at("lf");
  EXPECT_EQ(lf.label, "left front wheel (LF)");
  Click(0.5f * (lf.x0 + lf.x1), 0.5f * (lf.y0 + lf.y1));
  ASSERT_TRUE(FramesUntil(*v_, {}, [&] { return v_->params_editor().drawn().count("lf.radius"); }));
  const auto* w = pb::WheelParams::descriptor();
  for (int i = 0; i < w->field_count(); ++i) {
    // The tyre's file name travels only to the server (it sends the coefficients): not shown.
    if (w->field(i)->name() == "tire_file") continue;
    const std::string path = "lf." + w->field(i)->name();
    SCOPED_TRACE(path);
    ASSERT_EQ(v_->params_editor().drawn().count(path), 1u);
    EXPECT_EQ(v_->params_editor().drawn().at(path).label, limits::ParamWords(path));
  }
  EXPECT_EQ(v_->params_editor().drawn().at("lf.radius").label, "wheel radius, m");
  // The wheel's Magic Formula tyre shows its name on its group.
  EXPECT_EQ(v_->params_editor().drawn().at("lf.magic_formula").text, "synthetic 205/55 R16");
  EXPECT_EQ(v_->params_editor().drawn().at("b").label, "distance T to front axle, m");
}

TEST_F(ParamsPanel, TextTypedIntoAFieldNeverReachesTheHotkeys) {
  Open();
  ASSERT_EQ(v_->camera().mode, CameraMode::kMap);
  const auto mass = v_->params_editor().drawn().at("mass");
  // A click into the mass field and, arriving with it before the next frame, "1", "c", "p" and
  // "h": camera 1, next camera, the panel and the HUD if they reached the hotkeys.
  Click(mass.x0 + 20, 0.5f * (mass.y0 + mass.y1));
  Type("1cph");
  for (int i = 0; i < 3; ++i) v_->Frame();
  // More typed while the field has the input.
  Type("2l");
  for (int i = 0; i < 3; ++i) v_->Frame();
  EXPECT_EQ(v_->camera().mode, CameraMode::kMap) << "typing changed the camera";
  EXPECT_TRUE(v_->params_editor().drawn().count("mass")) << "typing closed the panel";
  EXPECT_FALSE(v_->hud_text().empty()) << "typing hid the HUD";
  // Enter ends the editing; then the keys are the viewer's again.
  // (A key pressed and released within one frame is lost to this ImGui: down, a frame, up.)
  ASSERT_TRUE(Xdo({"keydown", "--window", window_, "Return"}));
  for (int i = 0; i < 2; ++i) v_->Frame();
  ASSERT_TRUE(Xdo({"keyup", "--window", window_, "Return"}));
  for (int i = 0; i < 2; ++i) v_->Frame();
  Press("c");
  for (int i = 0; i < 2; ++i) v_->Frame();
  EXPECT_EQ(v_->camera().mode, CameraMode::kNorth) << "C after editing: the next camera";
}

TEST_F(ViewerApp, FollowingAVehicleThatIsNotThereSaysSoListsThoseThatAreAndWaitsForIt) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2, {1, 2, 7})));
  ViewerOptions o = Options(domain);
  o.follow = 7;
  Viewer v(o);
  TestVehicle a, b;
  a.id = 1;
  b.id = 2;
  b.x = 8;
  ExpectLogs logs;
  ASSERT_TRUE(FramesUntil(
      v,
      [&] {
        pub.State(MakeState(a));
        pub.State(MakeState(b));
      },
      [&] { return HudHas(v, "on the domain: 1, 2"); }))
      << Hud(v);
  EXPECT_TRUE(HudHas(v, "waiting for vehicle 7")) << Hud(v);
  EXPECT_FALSE(v.followed().has_value()) << "followed another vehicle instead";
  EXPECT_FALSE(v.ready());
  // It was said in the log too (once the others had a second to arrive).
  ASSERT_TRUE(FramesUntil(
      v,
      [&] {
        pub.State(MakeState(a));
        pub.State(MakeState(b));
      },
      [&] { return logs.count() > 0; }));
  // Vehicle 7 comes: followed.
  TestVehicle c;
  c.id = 7;
  c.x = -8;
  ASSERT_TRUE(FramesUntil(
      v,
      [&] {
        pub.State(MakeState(a));
        pub.State(MakeState(c));
      },
      [&] { return v.followed() == 7u; }));
  v.Frame();
  EXPECT_TRUE(HudHas(v, "vehicle 7  (3 on the domain")) << Hud(v);
}

TEST_F(ViewerApp, LandmarkNamesNeverOverlapAndFadeTowardsTheHorizon) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  // Forty landmarks in a row ahead of the vehicle, 5 m apart: their names crowd towards the
  // horizon of the chase camera.
  pb::WorldDescription w = MakeWorld("test", kPi / 2);
  for (int i = 0; i < 40; ++i) {
    pb::Landmark* l = w.add_landmarks();
    l->set_name("post " + std::to_string(i));
    l->mutable_p_w()->set_x(10 + 5.0 * i);
    l->mutable_p_w()->set_y(i % 2 == 0 ? 3 : -3);
  }
  ASSERT_TRUE(pub.World(w));
  ViewerOptions o = Options(domain);
  o.landmarks = true;
  Viewer v(o);
  Show(v, pub, {MakeState(TestVehicle{})});
  v.Frame();
  const auto& labels = v.labels();
  ASSERT_GT(labels.size(), 3u);
  std::set<std::string> names;
  for (std::size_t i = 0; i < labels.size(); ++i) {
    names.insert(labels[i].text);
    for (std::size_t j = i + 1; j < labels.size(); ++j) {
      EXPECT_FALSE(viewer::Overlap(labels[i].box, labels[j].box))
          << labels[i].text << " overlaps " << labels[j].text;
    }
  }
  EXPECT_TRUE(names.count("#1")) << "the followed vehicle's number";
  EXPECT_TRUE(names.count("post 0"));
  EXPECT_LT(labels.size(), 41u) << "nothing decluttered";
}

TEST_F(ViewerApp, LandmarksAreHiddenUntilTheKeyMShowsThem) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  pb::WorldDescription w = MakeWorld("test", kPi / 2);
  for (int i = 0; i < 3; ++i) {
    pb::Landmark* l = w.add_landmarks();
    l->set_name("post " + std::to_string(i));
    l->mutable_p_w()->set_x(15 + 10.0 * i);
    l->mutable_p_w()->set_y(4);
  }
  ASSERT_TRUE(pub.World(w));
  Viewer v(Options(domain));
  const Image hidden = Keep(Show(v, pub, {MakeState(TestVehicle{})}));
  auto landmark_labels = [&] {
    int n = 0;
    for (const auto& l : v.labels()) n += l.text.rfind("post ", 0) == 0 ? 1 : 0;
    return n;
  };
  EXPECT_EQ(landmark_labels(), 0) << "landmark names are shown by default";
  // Their orange markers are not drawn either.
  auto orange = [](const Image& img) {
    int n = 0;
    for (std::size_t k = 0; k + 3 < img.rgba.size(); k += 4) {
      const int r = img.rgba[k], g = img.rgba[k + 1], b = img.rgba[k + 2];
      n += r > 150 && g > 50 && g < 0.75 * r && b < 0.45 * g ? 1 : 0;
    }
    return n;
  };
  const int orange_hidden = orange(hidden);
  Key(SDLK_m);
  v.Frame();
  v.Frame();
  EXPECT_GT(landmark_labels(), 0) << "M did not show the landmarks' names";
  EXPECT_GT(orange(Keep(v.Screenshot())), orange_hidden + 20) << "M did not show their markers";
  Key(SDLK_m);
  v.Frame();
  v.Frame();
  EXPECT_EQ(landmark_labels(), 0) << "M did not hide them again";
}

}  // namespace
}  // namespace vdyn::testing
