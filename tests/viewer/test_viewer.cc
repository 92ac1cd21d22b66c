// vdyn-viewer in-process: a test publisher writes worlds, states and driver inputs on a fresh
// loopback domain, the viewer draws frames into its offscreen target under a private Xvfb
// (Mesa's llvmpipe), and the screenshots are checked by what they must show - computed here in
// closed form from the published poses and forces, not compared with stored images.
#include <gtest/gtest.h>

#include <SDL.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <limits>
#include <memory>

#include "../dds_wait.h"
#include "../process.h"
#include "../test_support.h"
#include "vdyn/base/time.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/physics/world.h"
#include "vdyn/viewer/camera.h"
#include "vdyn/viewer/car_model.h"
#include "vdyn/viewer/draw_list.h"
#include "vdyn/viewer/dressing.h"
#include "vdyn/viewer/lighting.h"
#include "vdyn/viewer/params_editor.h"
#include "vdyn/viewer/scene.h"
#include "vdyn/viewer/textures.h"
#include "vdyn/viewer/viewer.h"
#include "vdyn/viewer/world_mesh.h"
#include "viewer_support.h"

namespace vdyn::testing {
namespace {

using viewer::CameraMode;
using viewer::ForceColour;
using viewer::ForceKind;
using viewer::Image;
using viewer::kPi;
using viewer::Viewer;
using viewer::ViewerOptions;

constexpr int kW = 640, kH = 480;
constexpr int kTol = 12;  // per channel: arrows are unlit, in the legend's exact colours

class ViewerTest : public ::testing::Test {
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

  // Options for a scene's test: no HUD, at the quality and with the camera given.
  static ViewerOptions SceneOptions(std::uint32_t domain, viewer::Quality q, CameraMode mode) {
    ViewerOptions o = Options(domain);
    o.quality = q;
    o.hud = false;
    o.camera.mode = mode;
    return o;
  }

  // Frames until `done` (publishing before each one), at most 60 s; false on timeout.
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

  // Publishes the states until the viewer draws each at its step; returns the screenshot.
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

  // With VDYN_VIEWER_TEST_PNGS=DIR set, every screenshot checked is also written there (to look
  // at them), named after the test.
  static Image Keep(Image img) {
    static int n = 0;
    if (const char* dir = std::getenv("VDYN_VIEWER_TEST_PNGS")) {
      const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
      std::string name = std::string(info->test_suite_name()) + "." + info->name();
      for (char& c : name) {
        if (c == '/') c = '_';
      }
      viewer::WritePng(std::string(dir) + "/" + name + "-" + std::to_string(++n) + ".png", img);
    }
    return img;
  }

  static Xvfb* xvfb_;
};
Xvfb* ViewerTest::xvfb_ = nullptr;

// A pixel back on the ground, from the map's closed form (inverse of MapPixel), in the body frame
// of a vehicle at (x, y, yaw).
std::array<double, 2> PixelInBody(double px, double py, double cx, double cy, double up_yaw,
                                  double half_height, double x, double y, double yaw) {
  const double ppm = kH / (2.0 * half_height);
  const double right = (px - 0.5 * kW) / ppm, up = (0.5 * kH - py) / ppm;
  const double wx = cx + up * std::cos(up_yaw) + right * std::sin(up_yaw);
  const double wy = cy + up * std::sin(up_yaw) - right * std::cos(up_yaw);
  const double dx = wx - x, dy = wy - y;
  return {dx * std::cos(yaw) + dy * std::sin(yaw), -dx * std::sin(yaw) + dy * std::cos(yaw)};
}

// Orientation of a blob's pixels (the principal axis of their second moments), rad, in image
// axes (x right, y down).
double BlobAxis(const Image& img, viewer::Rgb8 c, Rect r) {
  const Blob b = FindColour(img, c.r, c.g, c.b, kTol, r);
  double sxx = 0, syy = 0, sxy = 0;
  for (int y = r.y0; y < std::min(r.y1, img.height); ++y) {
    for (int x = r.x0; x < std::min(r.x1, img.width); ++x) {
      const std::uint8_t* p = img.rgba.data() + (static_cast<std::size_t>(y) * img.width + x) * 4;
      if (std::abs(p[0] - c.r) > kTol || std::abs(p[1] - c.g) > kTol || std::abs(p[2] - c.b) > kTol)
        continue;
      const double dx = x + 0.5 - b.cx, dy = y + 0.5 - b.cy;
      sxx += dx * dx;
      syy += dy * dy;
      sxy += dx * dy;
    }
  }
  return 0.5 * std::atan2(2 * sxy, sxx - syy);
}

// --- the vehicles where they are -------------------------------------------------------------

class MapTest : public ViewerTest, public ::testing::WithParamInterface<double> {};

TEST_P(MapTest, EachVehicleIsDrawnWhereItIsTurnedAsItIs) {
  const double north_yaw = GetParam();
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", north_yaw, {1, 2})));
  ViewerOptions o = Options(domain);
  o.follow = 1;
  o.hud = false;
  o.camera.mode = CameraMode::kMap;
  o.camera.map_half_height = 12;
  Viewer v(o);
  TestVehicle a, b;
  a.id = 1;
  a.x = 10;
  a.y = 2;
  a.yaw = 0.5;
  b.id = 2;
  b.x = 16;
  b.y = -3;
  b.yaw = -0.4;
  for (TestVehicle* t : {&a, &b}) {
    for (auto& w : t->wheels) w.fp = 0;  // no arrows: only the bodies
  }
  const Image img = Show(v, pub, {MakeState(a), MakeState(b)});
  ASSERT_EQ(v.stats().worlds_accepted, 1u);

  for (const TestVehicle* t : {&a, &b}) {
    SCOPED_TRACE("vehicle " + std::to_string(t->id));
    const viewer::Rgb8 c = viewer::VehicleColour(t->id);
    // The roof is drawn in the vehicle's colour; every pixel of it lies inside the body box
    // published in the world (front, rear, half width), placed at the vehicle's pose.
    const auto centre = MapPixel(t->x, t->y, a.x, a.y, north_yaw, 12, kW, kH);
    const Rect around{static_cast<int>(centre[0]) - 80, static_cast<int>(centre[1]) - 80,
                      static_cast<int>(centre[0]) + 80, static_cast<int>(centre[1]) + 80};
    const Blob roof = FindColour(img, c.r, c.g, c.b, kTol, around);
    EXPECT_GT(roof.count, 400) << "vehicle not drawn near pixel (" << centre[0] << ", " << centre[1]
                               << ")";
    int outside = 0;
    for (int y = around.y0; y < around.y1; ++y) {
      for (int x = around.x0; x < around.x1; ++x) {
        if (x < 0 || y < 0 || x >= kW || y >= kH) continue;
        const std::uint8_t* p = img.rgba.data() + (static_cast<std::size_t>(y) * kW + x) * 4;
        if (std::abs(p[0] - c.r) > kTol || std::abs(p[1] - c.g) > kTol ||
            std::abs(p[2] - c.b) > kTol)
          continue;
        const auto body =
            PixelInBody(x + 0.5, y + 0.5, a.x, a.y, north_yaw, 12, t->x, t->y, t->yaw);
        const double tol = 2.0 * 24.0 / kH;  // two pixels, in metres
        if (body[0] > TestCar::kFront + tol || body[0] < -TestCar::kRear - tol ||
            std::abs(body[1]) > TestCar::kHalfWidth + tol) {
          ++outside;
        }
      }
    }
    EXPECT_EQ(outside, 0) << "pixels of the vehicle's colour outside its body box";
    // The roof is longer than wide: its long axis is the vehicle's heading on the screen.
    const double axis = BlobAxis(img, c, around);
    const double expected = -(t->yaw - north_yaw + kPi / 2);  // screen x right, y down
    EXPECT_NEAR(std::remainder(axis - expected, kPi), 0.0, 0.1)
        << "roof axis " << axis << " rad on screen, expected " << expected;
  }
}

INSTANTIATE_TEST_SUITE_P(NorthUpOrTurned, MapTest, ::testing::Values(kPi / 2, 0.3));

TEST_F(ViewerTest, VehiclesOfOtherServersAreDrawnOnlyWhenTheyShareTheTerrain) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  // Servers a and b run the same terrain (same terrain hash), c another one.
  for (const char* server : {"a", "b", "c"}) {
    pb::WorldDescription w = MakeWorld(server, kPi / 2, {1, 2, 3});
    w.set_terrain_hash(std::string(server) == "c" ? 0x2222u : 0x1111u);
    ASSERT_TRUE(pub.World(w));
  }
  ViewerOptions o = Options(domain);
  o.follow = 1;
  o.hud = false;
  o.camera.mode = CameraMode::kMap;
  o.camera.map_half_height = 12;
  Viewer v(o);
  std::vector<pb::VehicleState> states;
  const char* servers[] = {"a", "b", "c"};
  for (std::uint32_t id = 1; id <= 3; ++id) {
    TestVehicle t;
    t.id = id;
    t.server = servers[id - 1];
    t.x = 6.0 * (id - 1);
    for (auto& w : t.wheels) w.fp = 0;
    states.push_back(MakeState(t));
  }
  // Vehicle 3 is never drawn: wait for 1 and 2, and for 3's state to have arrived.
  ASSERT_TRUE(FramesUntil(
      v,
      [&] {
        for (const auto& s : states) pub.State(s);
      },
      [&] {
        const auto* sv = v.session().vehicle(3);
        return v.vehicle(1) != nullptr && v.vehicle(2) != nullptr && sv != nullptr &&
               sv->states > 0 && v.stats().worlds_accepted == 3;
      }));
  v.Frame();
  EXPECT_EQ(v.vehicle(3), nullptr);
  const Image img = Keep(v.Screenshot());
  for (std::uint32_t id = 1; id <= 3; ++id) {
    const viewer::Rgb8 c = viewer::VehicleColour(id);
    const auto p = MapPixel(6.0 * (id - 1), 0, 0, 0, kPi / 2, 12, kW, kH);
    const Rect around{static_cast<int>(p[0]) - 40, static_cast<int>(p[1]) - 40,
                      static_cast<int>(p[0]) + 40, static_cast<int>(p[1]) + 40};
    const int n = FindColour(img, c.r, c.g, c.b, kTol, around).count;
    if (id < 3) {
      EXPECT_GT(n, 400) << "vehicle " << id << " not drawn";
    } else {
      EXPECT_EQ(n, 0) << "vehicle 3 (another terrain) drawn";
    }
  }
}

// A vehicle its server no longer runs (removed, or the server started again without it) is
// forgotten once the server's diagnostics no longer list it: before, it stayed drawn, frozen,
// counted on the HUD and reachable with Tab for good. One whose server is silent stays.
TEST_F(ViewerTest, AVehicleItsServerNoLongerRunsIsForgotten) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("a", kPi / 2, {1, 2})));
  ViewerOptions o = Options(domain);
  o.follow = 1;
  o.hud = false;
  Viewer v(o);
  std::uint64_t step = 0;
  auto state = [&](std::uint32_t id) {
    TestVehicle t;
    t.id = id;
    t.server = "a";
    t.x = 6.0 * (id - 1);
    pb::VehicleState s = MakeState(t);
    s.set_step(step);
    return s;
  };
  auto diagnostics = [&](std::initializer_list<std::uint32_t> ids) {
    pb::Diagnostics d;
    d.set_server_id("a");
    d.set_steps(step);
    d.set_sim_time_ns(static_cast<std::int64_t>(step) * 1'000'000);
    for (std::uint32_t id : ids) d.add_vehicles()->set_vehicle_id(id);
    pub.Diagnostics(d);
  };
  auto both = [&] {  // a step of both vehicles, and diagnostics that list them
    ++step;
    pub.State(state(1));
    pub.State(state(2));
    diagnostics({1, 2});
  };
  // Tab pressed n times before one frame, then the frames that take them.
  auto tabs = [&](int n) {
    for (int k = 0; k < n; ++k) {
      SDL_Event tab{};
      tab.type = SDL_KEYDOWN;
      tab.key.keysym.sym = SDLK_TAB;
      SDL_PushEvent(&tab);
    }
    v.Frame();
    v.Frame();
  };
  ASSERT_TRUE(FramesUntil(v, both, [&] { return v.vehicle(1) != nullptr && v.vehicle(2) != nullptr; }));
  // Both listed while both send: a frame later both are still there.
  v.Frame();
  ASSERT_NE(v.vehicle(2), nullptr);
  // Tab pressed three times within one frame moves three places (1 -> 2 -> 1 -> 2): it moved one
  // place before (each press counted from the vehicle followed at the frame's start).
  both();
  tabs(3);
  EXPECT_EQ(v.followed(), std::optional<std::uint32_t>(2));
  tabs(2);
  EXPECT_EQ(v.followed(), std::optional<std::uint32_t>(2));  // two places: back to 2
  tabs(1);  // follow 1 again for the rest
  ASSERT_EQ(v.followed(), std::optional<std::uint32_t>(1));
  // Vehicle 2 removed: no more states of it, and the diagnostics list vehicle 1 alone.
  ASSERT_TRUE(FramesUntil(
      v,
      [&] {
        ++step;
        pub.State(state(1));
        diagnostics({1});
      },
      [&] { return v.vehicle(2) == nullptr; }));
  EXPECT_NE(v.vehicle(1), nullptr);
  EXPECT_EQ(v.session().vehicle(2), nullptr);
  // It comes back with a new state (spawned again).
  ASSERT_TRUE(FramesUntil(v, both, [&] { return v.vehicle(2) != nullptr; }));
}

// --- arrows ----------------------------------------------------------------------------------

// The tip of an arrow of `kind` on the map: the extreme pixel of its colour in the direction it
// points (right, left, up or down on the screen).
int TipAlong(const Image& img, ForceKind kind, char direction, Rect r) {
  const viewer::Rgb8 c = ForceColour(kind);
  const Blob b = FindColour(img, c.r, c.g, c.b, kTol, r);
  EXPECT_GT(b.count, 20) << viewer::ForceLabel(kind) << " arrow not found";
  switch (direction) {
    case 'r':
      return b.max_x + 1;
    case 'l':
      return b.min_x;
    case 'u':
      return b.min_y;
    default:
      return b.max_y + 1;
  }
}

// Which way an arrow in a band points: its head (the widest cross-section of its colour, 2.2
// times the shaft) lies towards that end of its span: 'r', 'l', 'u' or 'd'.
char HeadEnd(const Image& img, viewer::Rgb8 c, Rect band, bool horizontal) {
  const Blob b = FindColour(img, c.r, c.g, c.b, kTol, band);
  int best = 0, at = 0;
  const int from = horizontal ? b.min_x : b.min_y, to = horizontal ? b.max_x : b.max_y;
  for (int i = from; i <= to; ++i) {
    const Rect slice =
        horizontal ? Rect{i, band.y0, i + 1, band.y1} : Rect{band.x0, i, band.x1, i + 1};
    const int n = FindColour(img, c.r, c.g, c.b, kTol, slice).count;
    if (n > best) {
      best = n;
      at = i;
    }
  }
  const bool high = at - from > to - at;
  return horizontal ? (high ? 'r' : 'l') : (high ? 'd' : 'u');
}

TEST_F(ViewerTest, EachArrowPointsTheForcesWayInItsColourAndGrowsWithIt) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  ViewerOptions o = Options(domain);
  o.hud = false;
  o.camera.mode = CameraMode::kMap;
  const double hh = 8.0;
  o.camera.map_half_height = hh;
  Viewer v(o);
  const double scale = v.arrows().metres_per_newton;
  ASSERT_GT(scale, 0);

  auto run = [&](double f, std::uint64_t step) {
    TestVehicle t;
    t.step = step;
    t.speed = 5;  // rolling forward: the brake force points backwards
    for (auto& w : t.wheels) w.fp = 0;
    t.wheels[0].fh = f;     // LF drive: forwards (+X, east: right on a north-up map)
    t.wheels[0].fy = f;     // LF side, positive left (+Y, north: up)
    t.wheels[3].fb = f;     // RR brake: against the rolling (-X: left)
    t.da = f;               // drag: against +X, ending at the nose
    t.f_wall = {0, -f, 0};  // wall: -Y (down), from above the roof
    const Image img = Show(v, pub, {MakeState(t)});
    auto px = [&](double x, double y) { return MapPixel(x, y, 0, 0, kPi / 2, hh, kW, kH); };
    const double len = f * scale;
    struct Check {
      ForceKind kind;
      char dir;               // the far end of its span from the anchor
      char head;              // where it points
      double expected;        // pixel of that far end
      double base_x, base_y;  // the arrow's line
    };
    const auto lf = px(TestCar::kB, TestCar::kBl), rr = px(-TestCar::kC, -TestCar::kBp);
    const auto nose = px(TestCar::kFront, 0), roof = px(0, 0);
    const Check checks[] = {
        {ForceKind::kDrive, 'r', 'r', px(TestCar::kB + len, 0)[0], lf[0], lf[1]},
        {ForceKind::kSide, 'u', 'u', px(0, TestCar::kBl + len)[1], lf[0], lf[1]},
        {ForceKind::kBrake, 'l', 'l', px(-TestCar::kC - len, 0)[0], rr[0], rr[1]},
        // Drag ends at the nose, pointing back at it: its tail is ahead of the car.
        {ForceKind::kDrag, 'r', 'l', px(TestCar::kFront + len, 0)[0], nose[0], nose[1]},
        {ForceKind::kWall, 'd', 'd', px(0, -len)[1], roof[0], roof[1]},
    };
    std::map<ForceKind, int> tips;
    for (const Check& c : checks) {
      SCOPED_TRACE(std::string(viewer::ForceLabel(c.kind)) + ", " + std::to_string(f) + " N");
      // Search a band along the arrow's line only (several arrows share the picture).
      Rect band;
      if (c.dir == 'r' || c.dir == 'l') {
        band = {0, static_cast<int>(c.base_y) - 6, kW - 160, static_cast<int>(c.base_y) + 7};
      } else {
        band = {static_cast<int>(c.base_x) - 6, 0, static_cast<int>(c.base_x) + 7, kH};
      }
      const int tip = TipAlong(img, c.kind, c.dir, band);
      EXPECT_NEAR(tip, c.expected, 3.0) << "tip at pixel " << tip << ", expected " << c.expected;
      const bool horizontal = c.dir == 'r' || c.dir == 'l';
      EXPECT_EQ(HeadEnd(img, ForceColour(c.kind), band, horizontal), c.head)
          << "points the wrong way";
      // On the force's line: the colour's centroid across the band.
      const viewer::Rgb8 col = ForceColour(c.kind);
      const Blob b = FindColour(img, col.r, col.g, col.b, kTol, band);
      if (c.dir == 'r' || c.dir == 'l') {
        EXPECT_NEAR(b.cy, c.base_y, 2.0);
      } else {
        EXPECT_NEAR(b.cx, c.base_x, 2.0);
      }
      tips[c.kind] = tip;
    }
    return tips;
  };
  const auto small = run(2500, 10);
  const auto large = run(5000, 20);
  // Twice the force, twice the arrow: the tip moves by the first length again.
  const double ppm = kH / (2 * hh);
  EXPECT_NEAR(large.at(ForceKind::kDrive) - small.at(ForceKind::kDrive), 2500 * scale * ppm, 3);
  EXPECT_NEAR(small.at(ForceKind::kSide) - large.at(ForceKind::kSide), 2500 * scale * ppm, 3);
}

TEST_F(ViewerTest, SpringArrowPointsUpFromTheContactPointInASideView) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  ViewerOptions o = Options(domain);
  o.hud = false;
  o.camera.mode = CameraMode::kOrbit;
  o.camera.orbit_yaw = kPi / 2;  // looking from the vehicle's left (+Y) towards it
  o.camera.orbit_pitch = 0;
  o.camera.orbit_distance = 10;
  Viewer v(o);
  const double scale = v.arrows().metres_per_newton;
  const double fovy = o.camera.fovy;
  // The pinhole of that camera: at T + (0, 10, 0) looking along -Y, +Z up; screen right is -X.
  auto pixel = [&](double x, double y, double z) {
    const double ex = 0, ey = 10, ez = TestCar::kHeight;  // the orbit looks at T
    const double xc = -(x - ex), yc = z - ez, depth = -(y - ey);
    const double f = 0.5 * kH / std::tan(0.5 * fovy);
    return std::array<double, 2>{0.5 * kW + f * xc / depth, 0.5 * kH - f * yc / depth};
  };
  std::map<double, int> tops;
  for (double fp : {2500.0, 5000.0}) {
    TestVehicle t;
    t.step = fp == 2500.0 ? 5 : 6;
    for (auto& w : t.wheels) w.fp = 400;  // the other wheels: short arrows, below the LF tip
    t.wheels[0].fp = fp;
    const Image img = Show(v, pub, {MakeState(t)});
    const auto base = pixel(TestCar::kB, TestCar::kBl, TestCar::kGround);
    const auto tip = pixel(TestCar::kB, TestCar::kBl, TestCar::kGround + fp * scale);
    const viewer::Rgb8 g = ForceColour(ForceKind::kSpring);
    const Rect column{static_cast<int>(base[0]) - 6, 0, static_cast<int>(base[0]) + 7, kH};
    const Blob b = FindColour(img, g.r, g.g, g.b, kTol, column);
    ASSERT_GT(b.count, 20) << "no spring arrow above the LF contact point";
    EXPECT_NEAR(b.min_y, tip[1], 3.0) << "spring arrow of " << fp << " N";
    EXPECT_NEAR(b.cx, base[0], 2.0);
    EXPECT_LT(b.min_y, base[1]);  // upwards from B
    tops[fp] = b.min_y;
  }
  // Twice the force, twice as tall (perspective at one depth: linear in height).
  const auto b0 = pixel(TestCar::kB, TestCar::kBl, TestCar::kGround);
  EXPECT_NEAR(b0[1] - tops[5000.0], 2.0 * (b0[1] - tops[2500.0]), 4.0);
}

// --- the compass and the paddles -------------------------------------------------------------

// The needle's angle, counter-clockwise from up, from the red needle's centroid about the dial.
double NeedleAngle(const Image& img) {
  const double cx = kW - 75, cy = 75;
  const Blob b = FindColour(img, 235, 40, 40, kTol, {kW - 140, 10, kW - 10, 140});
  EXPECT_GT(b.count, 30) << "no compass needle";
  return std::atan2(-(b.cx - cx), -(b.cy - cy));
}

TEST_F(ViewerTest, PaddlePressesAndKeysTurnTheNorthCameraAndItsCompass) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  ViewerOptions o = Options(domain);
  o.camera.mode = CameraMode::kNorth;
  o.playback = true;  // the paper's use: the paddles turn the camera in playback (test below)
  Viewer v(o);
  TestVehicle t;
  Image img = Show(v, pub, {MakeState(t)});
  EXPECT_NEAR(NeedleAngle(img), 0.0, 0.09) << "north camera: north straight ahead";

  // The driver's rig: nothing pressed, then the right paddle.
  auto input_seen = [&](std::uint64_t n) {
    return FramesUntil(v, {}, [&] {
      const auto* sv = v.session().vehicle(1);
      return sv != nullptr && sv->input && sv->input->sequence() >= n;
    });
  };
  ASSERT_TRUE(pub.Input(1, 0));
  ASSERT_TRUE(input_seen(1));
  EXPECT_EQ(v.stats().paddle_presses, 0u);
  ASSERT_TRUE(pub.Input(1, pb::BUTTON_PADDLE_RIGHT));
  ASSERT_TRUE(FramesUntil(v, {}, [&] { return v.stats().paddle_presses == 1; }));
  img = Keep(v.Screenshot());
  // The view turned clockwise by one step (45 deg): north is now 45 deg to the left.
  EXPECT_NEAR(NeedleAngle(img), viewer::Rad(45), 0.09);
  // Holding the paddle is one press, not one per message.
  ASSERT_TRUE(pub.Input(1, pb::BUTTON_PADDLE_RIGHT));
  ASSERT_TRUE(input_seen(3));
  for (int i = 0; i < 3; ++i) v.Frame();
  EXPECT_EQ(v.stats().paddle_presses, 1u);

  // Q turns the view back counter-clockwise (the key path of the same turn).
  SDL_Event key{};
  key.type = SDL_KEYDOWN;
  key.key.keysym.sym = SDLK_q;
  SDL_PushEvent(&key);
  v.Frame();
  v.Frame();
  EXPECT_NEAR(NeedleAngle(Keep(v.Screenshot())), 0.0, 0.09);
  // Release, then the left paddle: counter-clockwise, north to the right.
  ASSERT_TRUE(pub.Input(1, 0));
  ASSERT_TRUE(input_seen(4));
  ASSERT_TRUE(pub.Input(1, pb::BUTTON_PADDLE_LEFT));
  ASSERT_TRUE(FramesUntil(v, {}, [&] { return v.stats().paddle_presses == 2; }));
  EXPECT_NEAR(NeedleAngle(Keep(v.Screenshot())), viewer::Rad(-45), 0.09);
}

// --- bad input -------------------------------------------------------------------------------

TEST_F(ViewerTest, MalformedWorldsAndStatesAreRefusedCountedAndTheViewGoesOn) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  ViewerOptions o = Options(domain);
  o.hud = false;
  o.camera.mode = CameraMode::kMap;
  o.camera.map_half_height = 12;
  Viewer v(o);
  TestVehicle t;
  for (auto& w : t.wheels) w.fp = 0;
  Image img = Show(v, pub, {MakeState(t)});
  const viewer::Rgb8 road = viewer::LookOf(pb::SURFACE_ROAD).colour;
  const Rect road_band{0, kH / 2 + 40, kW - 160, kH / 2 + 70};  // 2..3.5 m south of the car
  ASSERT_GT(FindColour(img, road.r, road.g, road.b, 6, road_band).count, 5000) << "no road";

  ExpectLogs expected;
  // A mesh whose index points past its vertices, then one with a stray coordinate.
  pb::WorldDescription bad = MakeWorld("test", kPi / 2);
  bad.mutable_meshes(1)->set_indices(2, 99);
  ASSERT_TRUE(pub.World(bad));
  ASSERT_TRUE(FramesUntil(v, {}, [&] { return v.stats().worlds_refused == 1; }));
  EXPECT_NE(v.stats().last_refusal.find("points past the last of 4 vertices"), std::string::npos)
      << v.stats().last_refusal;
  bad = MakeWorld("test", kPi / 2);
  bad.mutable_meshes(0)->add_vertices(1.0);
  ASSERT_TRUE(pub.World(bad));
  ASSERT_TRUE(FramesUntil(v, {}, [&] { return v.stats().worlds_refused == 2; }));
  EXPECT_NE(v.stats().last_refusal.find("not a multiple of 3"), std::string::npos);
  EXPECT_EQ(v.stats().worlds_accepted, 1u);

  // A state with a NaN (the transport drops and counts it) and one with three wheels (the
  // viewer refuses and counts it); the vehicle stays where its last good state put it.
  TestVehicle moved = t;
  moved.x = 5;
  moved.step = 2;
  pb::VehicleState nan_state = MakeState(moved);
  nan_state.mutable_wheels(0)->set_fh(std::nan(""));
  pb::VehicleState three = MakeState(moved);
  three.mutable_wheels()->RemoveLast();
  // (One kind at a time: the state topic keeps only the newest sample of a vehicle.)
  ASSERT_TRUE(FramesUntil(
      v, [&] { pub.State(nan_state); },
      [&] { return v.session().drops().Of("non-finite value on vdyn/states") > 0; }));
  ASSERT_TRUE(FramesUntil(
      v, [&] { pub.State(three); }, [&] { return v.stats().states_refused > 0; }));
  ASSERT_NE(v.vehicle(1), nullptr);
  EXPECT_EQ(v.vehicle(1)->step, 1u);
  EXPECT_DOUBLE_EQ(v.vehicle(1)->pose_WB.t.x, 0.0);
  EXPECT_NE(v.stats().last_refusal.find("3 wheels, expected 4"), std::string::npos);

  // It keeps drawing: the old world (road) and the next good state.
  img = Show(v, pub, {MakeState(moved)});
  EXPECT_GT(FindColour(img, road.r, road.g, road.b, 6, road_band).count, 5000);
  EXPECT_DOUBLE_EQ(v.vehicle(1)->pose_WB.t.x, 5.0);
  EXPECT_GE(expected.count(), 2);
}

TEST_F(ViewerTest, AWorldArrivingWithNoVehicleIsDrawnAroundItsSpawn) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  pb::WorldDescription w = MakeWorld("test", kPi / 2, {});
  w.mutable_spawn()->set_x(0);
  w.mutable_spawn()->set_y(0);
  ASSERT_TRUE(pub.World(w));
  ViewerOptions o = Options(domain);
  o.hud = false;
  o.camera.mode = CameraMode::kMap;
  o.camera.map_half_height = 12;
  Viewer v(o);
  ASSERT_TRUE(FramesUntil(v, {}, [&] { return v.stats().worlds_accepted == 1; }));
  v.Frame();
  const Image img = Keep(v.Screenshot());
  const viewer::Rgb8 road = viewer::LookOf(pb::SURFACE_ROAD).colour;
  // The road (8 m wide along X through the spawn) across the middle of the map, ground beside.
  const Blob r =
      FindColour(img, road.r, road.g, road.b, 6, {0, kH / 2 - 70, kW - 160, kH / 2 + 70});
  EXPECT_GT(r.count, 100 * 100);
  EXPECT_NEAR(r.cy, kH / 2.0, 3.0);
  EXPECT_EQ(FindColour(img, road.r, road.g, road.b, 6, {0, 0, kW - 160, kH / 2 - 100}).count, 0);
}

// --- the look: sun, shadow, sky --------------------------------------------------------------

// Mean of a channel-averaged colour over the map pixels of a world rectangle, in linear light
// (sRGB decoded: shading multiplies light, the ratio of two surfaces is a ratio of irradiance).
double MeanLinear(const Image& img, double x0, double y0, double x1, double y1, double half_m) {
  const auto a = MapPixel(x0, y1, 0, 0, kPi / 2, half_m, kW, kH);  // top left (north-west)
  const auto b = MapPixel(x1, y0, 0, 0, kPi / 2, half_m, kW, kH);  // bottom right
  double sum = 0;
  int n = 0;
  for (int y = static_cast<int>(a[1]); y < static_cast<int>(b[1]); ++y) {
    for (int x = static_cast<int>(a[0]); x < static_cast<int>(b[0]); ++x) {
      const std::uint8_t* p = img.rgba.data() + (static_cast<std::size_t>(y) * kW + x) * 4;
      for (int c = 0; c < 3; ++c) {
        const double u = p[c] / 255.0;
        sum += u <= 0.04045 ? u / 12.92 : std::pow((u + 0.055) / 1.055, 2.4);
      }
      ++n;
    }
  }
  return n > 0 ? sum / (3.0 * n) : 0.0;
}

// The sun stands 48 deg up in the south-west: a car's body throws its shadow to the north-east,
// out to about 0.9 m (the beltline) beyond its north side on the road. Seen from above, the road
// north of the car is darker than the same strip south of it, where the sun shines - by about the
// sky's share of the light (lighting.h: a face in shadow keeps about 30 %). At --quality low there
// is no shadow map: both strips are lit alike (what darkens near the car then is only the contact
// shadow, the same on both sides).
TEST_F(ViewerTest, TheSunsShadowDarkensTheRoadOnTheCarsFarSideOnlyWithShadows) {
  for (const viewer::Quality q : {viewer::Quality::kHigh, viewer::Quality::kLow}) {
    SCOPED_TRACE(std::string("quality ") + std::string(viewer::QualityName(q)));
    const std::uint32_t domain = FreshDomain();
    TestPublisher pub(domain);
    ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
    ViewerOptions o = Options(domain);
    o.quality = q;
    o.hud = false;
    o.camera.mode = CameraMode::kMap;
    o.camera.map_half_height = 6;
    Viewer v(o);
    TestVehicle t;
    for (auto& w : t.wheels) w.fp = 0;  // no arrows
    const Image img = Show(v, pub, {MakeState(t)});
    // Strips 1.2 .. 1.45 m from the car's axis (its side at 0.9 m, the contact shadow to 1.1 m),
    // along its length shifted east as the shadow is.
    const double north = MeanLinear(img, -1.0, 1.2, 1.5, 1.45, 6);
    const double south = MeanLinear(img, -1.0, -1.45, 1.5, -1.2, 6);
    ASSERT_GT(south, 0.02) << "the road south of the car is black";
    const double ratio = north / south;
    RecordProperty(std::string("north_over_south_") + std::string(viewer::QualityName(q)),
                   std::to_string(ratio));
    std::printf("quality %s: the road north of the car %.3f, south %.3f (linear), ratio %.3f\n",
                std::string(viewer::QualityName(q)).c_str(), north, south, ratio);
    if (q == viewer::Quality::kHigh) {
      EXPECT_GT(ratio, 0.2) << "the shadow is black: no sky light in it";
      EXPECT_LT(ratio, 0.42) << "no sun shadow north-east of the car";
    } else {
      EXPECT_NEAR(ratio, 1.0, 0.1) << "a shadow without the shadow map";
    }
    // The car itself is drawn (its roof in its colour) in both.
    const viewer::Rgb8 c = viewer::VehicleColour(1);
    EXPECT_GT(FindColour(img, c.r, c.g, c.b, 16).count, 1000);
  }
}

// The sky is a gradient: a deep blue overhead, paler towards the horizon (the fog's colour there).
// Without it the view would be one flat colour above the ground.
TEST_F(ViewerTest, TheSkyIsDeeperBlueOverheadThanTowardsTheHorizon) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  ViewerOptions o = Options(domain);
  o.quality = viewer::Quality::kLow;  // no clouds
  o.hud = false;
  o.camera.mode = CameraMode::kDriver;
  o.camera.fovy = viewer::Rad(90);  // from the horizon in the middle to 45 deg up at the top
  o.camera.driver_pitch = 0;        // level
  o.camera.cockpit = false;         // (its A-pillar and roof would stand in the sky)
  Viewer v(o);
  TestVehicle t;
  const Image img = Show(v, pub, {MakeState(t)});
  struct Band {
    double r = 0, g = 0, b = 0;
  };
  const auto band = [&](int y0, int y1) {
    Band m;
    int n = 0;
    for (int y = y0; y < y1; ++y) {
      for (int x = 0; x < kW; ++x) {
        const std::uint8_t* p = img.rgba.data() + (static_cast<std::size_t>(y) * kW + x) * 4;
        m.r += p[0];
        m.g += p[1];
        m.b += p[2];
        ++n;
      }
    }
    m.r /= n;
    m.g /= n;
    m.b /= n;
    return m;
  };
  const Band top = band(0, 8);                      // about 44 deg up
  const Band low = band(kH / 2 - 40, kH / 2 - 30);  // about 5 deg up
  for (const Band& s : {top, low}) EXPECT_GT(s.b, s.r + 15) << "not sky blue";
  EXPECT_GT(top.b - top.r, low.b - low.r + 30) << "no deeper blue overhead";
  EXPECT_LT(top.r + top.g + top.b, low.r + low.g + low.b - 60) << "not paler at the horizon";
}

// Fog: the ground fades to the horizon's colour with distance, as a person sees it from a hill.
// Seen from 20 m up across flat grass, each ground pixel's distance follows from its view ray;
// pixels are grouped by distance (as fractions of the far plane's distance, where the drawn world
// ends and the fog must hide it), and the colour of each group's mean is compared with the
// horizon's colour H (lighting.h, the sky's colour at the horizon). Near the eye the grass keeps
// its own colour; every farther group lies closer to H than the one before, and the farthest
// (about 0.8 of the way to the far plane, just short of the far hills) has gone most of the way.
// Without fog the far grass keeps the near grass's colour.
TEST_F(ViewerTest, TheGroundFadesToTheFogColourWithDistance) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  ViewerOptions o = SceneOptions(domain, viewer::Quality::kLow, CameraMode::kOrbit);
  o.camera.orbit_distance = 50;
  o.camera.orbit_pitch = viewer::Rad(24);  // the eye about 20 m up
  o.camera.orbit_yaw = viewer::Rad(90);    // north of the car, looking south across the road
  Viewer v(o);
  TestVehicle t;
  const Image img = Show(v, pub, {MakeState(t)});
  const viewer::CameraView& cam = v.last_camera();
  ASSERT_FALSE(cam.orthographic);
  const viewer::Mat4 inv = viewer::Inverse(cam.proj * cam.view);
  // The far plane's distance, from the projection: -(far + near) / (far - near) and
  // -2 far near / (far - near) in its third row.
  const double far_m = cam.proj(2, 3) / (cam.proj(2, 2) + 1.0);
  const viewer::Vec3 H = viewer::SceneLighting().horizon_rgb;
  struct Group {
    double lo_m, hi_m;
    viewer::Vec3 sum;  // linear colour
    int n = 0;
  };
  std::vector<Group> groups;
  for (auto [lo, hi] : {std::pair{0.077, 0.11}, {0.25, 0.3}, {0.5, 0.6}, {0.72, 0.82}}) {
    groups.push_back({lo * far_m, hi * far_m, {}});
  }
  const auto decode = [](std::uint8_t c) {
    const double u = c / 255.0;
    return u <= 0.04045 ? u / 12.92 : std::pow((u + 0.055) / 1.055, 2.4);
  };
  for (int y = 0; y < kH; ++y) {
    for (int x = 0; x < kW; ++x) {
      const double nx = 2.0 * (x + 0.5) / kW - 1, ny = 1 - 2.0 * (y + 0.5) / kH;
      const viewer::Vec3 a = inv.TransformPoint({nx, ny, -1}), b = inv.TransformPoint({nx, ny, 1});
      const viewer::Vec3 dir = viewer::Normalized(b - a);
      if (dir.z > -1e-4) continue;            // the sky
      if (x > kW - 150 && y < 150) continue;  // the compass
      const double s = -cam.eye_W.z / dir.z;  // to the ground, z = 0
      const viewer::Vec3 g = cam.eye_W + dir * s;
      if (std::abs(g.y) < 8) continue;  // the road and its kerbs (8 m wide along X at y = 0)
      for (Group& gr : groups) {
        if (s < gr.lo_m || s >= gr.hi_m) continue;
        const std::uint8_t* p = img.rgba.data() + (static_cast<std::size_t>(y) * kW + x) * 4;
        gr.sum = gr.sum + viewer::Vec3{decode(p[0]), decode(p[1]), decode(p[2])};
        ++gr.n;
      }
    }
  }
  for (const Group& gr : groups) ASSERT_GT(gr.n, 200) << "too few ground pixels at " << gr.lo_m;
  const double near_from_fog = viewer::Norm(groups.front().sum / groups.front().n - H);
  ASSERT_GT(near_from_fog, 0.2) << "the grass is the fog's colour even nearby";
  double last = 1.0;  // the nearest group's own
  for (std::size_t i = 1; i < groups.size(); ++i) {
    const Group& gr = groups[i];
    const double seen = viewer::Norm(gr.sum / gr.n - H) / near_from_fog;
    std::printf("ground %4.0f-%4.0f m: |C - H| over the nearest group's %.3f (%d pixels)\n",
                gr.lo_m, gr.hi_m, seen, gr.n);
    EXPECT_LT(seen, last - 0.05) << "not fading towards the horizon's colour at " << gr.lo_m
                                 << " m";
    last = seen;
  }
  EXPECT_LT(last, 0.35) << "the farthest ground is not mostly fog";
}

// Materials, seen from straight above in the map view at quality high: four patches of a model
// body, each 1.4 x 1.6 m. The same grey (180) as chrome and as matte plastic: a smooth metal has
// no diffuse part and mirrors the sky in its own colour, so from above it shows the zenith's deep
// blue (lighting.h: blue over red about 5) darkened by its grey; the matte patch diffuses the
// sun's and the sky's light, near white (blue over red near 1). The vehicle's paint under its
// clear coat flat, and tilted so that its normal halves the angle between the sun and the eye:
// the clear coat mirrors the sun there, a highlight whose linear value is well above 1 (about
// twice the sun's light on a white face); the filmic tone mapping rolls it off towards white
// without clipping it.
viewer::ModelMesh MaterialPatches() {
  viewer::ModelMesh m;
  const viewer::Lighting& l = viewer::SceneLighting();
  const viewer::Vec3 h = viewer::Normalized(l.sun_W + viewer::Vec3{0, 0, 1});  // sun and the eye
  auto quad = [&](double x0, viewer::Vec3 n, viewer::Material mat, std::uint8_t grey) {
    const auto base = static_cast<std::uint32_t>(m.vertices.size());
    const double xc = x0 + 0.7;
    for (const auto& [dx, dy] : {std::pair{-0.7, -0.8}, {0.7, -0.8}, {0.7, 0.8}, {-0.7, 0.8}}) {
      viewer::ModelVertex v{};
      const double z = 1.0 - (n.x * dx + n.y * dy) / n.z;  // the plane through (xc, 0, 1)
      v.p[0] = static_cast<float>(xc + dx);
      v.p[1] = static_cast<float>(dy);
      v.p[2] = static_cast<float>(z);
      v.n[0] = static_cast<float>(n.x);
      v.n[1] = static_cast<float>(n.y);
      v.n[2] = static_cast<float>(n.z);
      v.rgba[0] = v.rgba[1] = v.rgba[2] = grey;
      v.rgba[3] = 255;
      v.material[0] = static_cast<std::uint8_t>(mat);
      m.vertices.push_back(v);
    }
    m.indices.insert(m.indices.end(), {base, base + 1, base + 2, base, base + 2, base + 3});
  };
  quad(0.0, {0, 0, 1}, viewer::Material::kChrome, 180);
  quad(1.6, {0, 0, 1}, viewer::Material::kMatte, 180);
  quad(3.2, h, viewer::Material::kPaint, 255);
  quad(4.8, {0, 0, 1}, viewer::Material::kPaint, 255);
  m.min = m.fit_min = {0, -0.8, 0};
  m.max = m.fit_max = {6.2, 0.8, 1.5};
  return m;
}

TEST_F(ViewerTest, MetalMirrorsTheSkyMatteDiffusesAndAClearCoatHighlightIsNotClipped) {
  const auto model = std::make_shared<const viewer::ModelMesh>(MaterialPatches());
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2)));
  ViewerOptions o = SceneOptions(domain, viewer::Quality::kHigh, CameraMode::kMap);
  o.camera.map_half_height = 4;
  o.car_model = model;
  Viewer v(o);
  TestVehicle t;
  for (auto& w : t.wheels) w.fp = 0;  // no arrows
  const Image img = Show(v, pub, {MakeState(t)});
  const viewer::VehicleView* view = v.vehicle(t.id);
  ASSERT_NE(view, nullptr);
  const viewer::Mat4 fit = viewer::FitModel(*model, view->geometry, false);
  // The mean colour (linear) of 13 x 13 pixels at a patch's centre.
  auto patch = [&](double x0) {
    const viewer::Vec3 c_W = view->pose_WB * fit.TransformPoint({x0 + 0.7, 0, 1});
    const auto px =
        MapPixel(c_W.x, c_W.y, view->pose_WB.t.x, view->pose_WB.t.y, kPi / 2, 4, kW, kH);
    viewer::Vec3 sum;
    int top = 0;
    for (int y = static_cast<int>(px[1]) - 6; y <= static_cast<int>(px[1]) + 6; ++y) {
      for (int x = static_cast<int>(px[0]) - 6; x <= static_cast<int>(px[0]) + 6; ++x) {
        const std::uint8_t* p = img.rgba.data() + (static_cast<std::size_t>(y) * kW + x) * 4;
        sum = sum +
              viewer::Vec3{viewer::ToLinear(p[0]), viewer::ToLinear(p[1]), viewer::ToLinear(p[2])};
        top =
            std::max({top, static_cast<int>(p[0]), static_cast<int>(p[1]), static_cast<int>(p[2])});
      }
    }
    return std::pair{sum / 169.0, top};
  };
  const auto [chrome, chrome_top] = patch(0.0);
  const auto [matte, matte_top] = patch(1.6);
  const auto [highlight, highlight_top] = patch(3.2);
  const auto [paint, paint_top] = patch(4.8);
  std::printf(
      "linear rgb: chrome %.3f %.3f %.3f, matte %.3f %.3f %.3f, paint %.3f %.3f %.3f, "
      "paint at the sun's mirror angle %.3f %.3f %.3f (brightest byte %d)\n",
      chrome.x, chrome.y, chrome.z, matte.x, matte.y, matte.z, paint.x, paint.y, paint.z,
      highlight.x, highlight.y, highlight.z, highlight_top);
  EXPECT_GT(chrome.z, 2.5 * chrome.x) << "the chrome does not mirror the deep blue overhead";
  EXPECT_LT(chrome.x, 0.6 * matte.x) << "the chrome has a diffuse part";
  EXPECT_LT(matte.z, 1.3 * matte.x) << "the matte patch is not lit white by the sun";
  EXPECT_GT(matte.x, 0.25) << "the matte patch is dark";
  // The highlight: near white over the paint's blue (vehicle 1: red 90 of 255), not clipped.
  EXPECT_GT(highlight.x, paint.x + 0.4) << "no clear-coat highlight of the sun";
  EXPECT_GT(highlight.x, 0.7);
  EXPECT_LT(highlight_top, 253) << "the highlight is clipped to white";
}

TEST_F(ViewerTest, TheStatusPanelStaysClearOfTheCompassInANarrowWindow) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  TestVehicle t;
  t.server = "the-simulation-server-of-the-driving-lab-upstairs";
  ASSERT_TRUE(pub.World(MakeWorld(t.server, kPi / 2)));
  ViewerOptions o = Options(domain);
  ASSERT_TRUE(o.hud);
  Viewer v(o);
  Show(v, pub, {MakeState(t)});
  // A few frames more: ImGui sizes a panel that fits its contents from the frame before.
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(v.Frame());
  Keep(v.Screenshot());
  const std::vector<viewer::LabelBox>& boxes = v.hud_boxes();
  ASSERT_GE(boxes.size(), 2u);
  const viewer::LabelBox& status = boxes.front();
  const viewer::LabelBox& compass = boxes.back();
  EXPECT_LT(status.x0, 20) << "not the status panel at the top left";
  EXPECT_GT(compass.x0, kW / 2) << "not the compass at the top right";
  EXPECT_FALSE(viewer::Overlap(status, compass))
      << "the status panel reaches x = " << status.x1 << ", the compass starts at " << compass.x0;
}

// Live, a full-model car's paddles are its gearbox: a shift no longer turns the geographic camera
// (every gear change turned the map). A paper-model car has no gearbox: its paddles still do.
TEST_F(ViewerTest, LiveTheGearboxsPaddlesLeaveTheCameraAlone) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2, {1, 2})));
  ViewerOptions o = Options(domain);
  o.camera.mode = CameraMode::kNorth;
  o.follow = 1;
  Viewer v(o);
  TestVehicle full;
  pb::VehicleState s1 = MakeState(full);
  s1.set_model(pb::VEHICLE_MODEL_FULL);
  Show(v, pub, {s1});
  auto input_seen = [&](std::uint32_t vehicle, std::uint64_t n) {
    return FramesUntil(v, {}, [&] {
      const auto* sv = v.session().vehicle(vehicle);
      return sv != nullptr && sv->input && sv->input->sequence() >= n;
    });
  };
  ASSERT_TRUE(pub.Input(1, 0));
  ASSERT_TRUE(input_seen(1, 1));
  ASSERT_TRUE(pub.Input(1, pb::BUTTON_PADDLE_RIGHT));  // a gear up
  ASSERT_TRUE(input_seen(1, 2));
  for (int i = 0; i < 3; ++i) v.Frame();
  EXPECT_EQ(v.stats().paddle_presses, 0u);
  EXPECT_NEAR(NeedleAngle(Keep(v.Screenshot())), 0.0, 0.09) << "the camera turned on a shift";
  // The paper model's car (no gearbox): its paddle turns the camera, live too.
  pb::VehicleState s2 = s1;
  s2.set_model(pb::VEHICLE_MODEL_PAPER);
  s2.set_step(s1.step() + 1);
  Show(v, pub, {s2});
  ASSERT_TRUE(pub.Input(1, 0));
  ASSERT_TRUE(input_seen(1, 3));
  ASSERT_TRUE(pub.Input(1, pb::BUTTON_PADDLE_RIGHT));
  ASSERT_TRUE(FramesUntil(v, {}, [&] { return v.stats().paddle_presses == 1; }));
  EXPECT_NEAR(NeedleAngle(Keep(v.Screenshot())), viewer::Rad(45), 0.09);
  // The wheel's camera button: the next camera (north -> beside), as C (nothing read it).
  ASSERT_EQ(v.options().camera.mode, CameraMode::kNorth);
  ASSERT_TRUE(pub.Input(1, pb::BUTTON_CAMERA));
  ASSERT_TRUE(FramesUntil(v, {}, [&] { return v.stats().camera_buttons == 1; }));
  EXPECT_EQ(v.options().camera.mode, CameraMode::kBeside);
}

// --- drawn straight into the window ---------------------------------------------------------------

// A visible window without multisampling gets the scene and the HUD in its own back buffer (no
// copy a frame): the picture is the one drawn into a target of its own and copied, and the
// image a run of `frames` ends with is kept although the window's buffer is gone after the swap.
TEST_F(ViewerTest, TheSceneDrawnInTheWindowIsTheSceneDrawnApart) {
  const std::uint32_t domain = FreshDomain();
  TestPublisher pub(domain);
  ASSERT_TRUE(pub.World(MakeWorld("test", kPi / 2, {1, 2})));
  std::vector<pb::VehicleState> states;
  for (std::uint32_t id = 1; id <= 2; ++id) {
    TestVehicle t;
    t.id = id;
    t.x = 5.0 * (id - 1);
    states.push_back(MakeState(t));
  }
  auto draw = [&](bool in_window, bool* drawn_in_window) {
    ViewerOptions o = SceneOptions(domain, viewer::Quality::kLow, CameraMode::kMap);
    o.camera.map_half_height = 12;
    o.follow = 1;
    o.hidden = false;
    o.in_window = in_window;
    o.frames = 3;
    Viewer v(o);
    const auto deadline = base::MonotonicNow() + base::Seconds(60);
    bool ended = false;
    while (!ended && base::MonotonicNow() < deadline) {
      for (const auto& s : states) pub.State(s);
      ended = !v.Frame();
    }
    EXPECT_TRUE(ended) << "the run of 3 frames did not end within 60 s";
    *drawn_in_window = v.stats().drawn_in_window;
    return Keep(v.Screenshot());
  };
  bool window_a = false, window_b = true;
  const Image a = draw(true, &window_a);
  const Image b = draw(false, &window_b);
  EXPECT_TRUE(window_a) << "not drawn in the window";
  EXPECT_FALSE(window_b);
  ASSERT_EQ(a.width, kW);
  ASSERT_EQ(a.height, kH);
  ASSERT_EQ(b.width, kW);
  ASSERT_EQ(b.height, kH);
  // Both vehicles are there (not a blank or stale buffer), and every pixel is the same.
  for (std::uint32_t id = 1; id <= 2; ++id) {
    const viewer::Rgb8 c = viewer::VehicleColour(id);
    EXPECT_GT(FindColour(a, c.r, c.g, c.b, kTol, Rect{0, 0, kW, kH}).count, 100) << id;
  }
  // The same picture: Mesa's llvmpipe rounds a handful of pixels (5 of 921,600) one step apart
  // in the window's pixel format and the target's; none further.
  std::size_t one_step = 0, further = 0;
  std::string where;
  for (std::size_t i = 0; i < a.rgba.size(); i += 4) {
    int d = 0;
    for (int c = 0; c < 3; ++c) d = std::max(d, std::abs(a.rgba[i + c] - b.rgba[i + c]));
    if (d == 0) continue;
    (d == 1 ? one_step : further) += 1;
    if (d > 1 && further <= 8) {
      where += " (" + std::to_string(i / 4 % kW) + ", " + std::to_string(i / 4 / kW) + ")";
      for (int c = 0; c < 3; ++c) {
        where += " " + std::to_string(a.rgba[i + c]) + "/" + std::to_string(b.rgba[i + c]);
      }
    }
  }
  EXPECT_EQ(further, 0u) << "pixels that differ between the window and the target of its own:"
                         << where;
  EXPECT_LT(one_step, a.rgba.size() / 4 / 1000) << "pixels one step apart";
}

// --- the wheels turn with the published wheel speed ---------------------------------------------

// The test car's geometry, as the test world describes it.
viewer::VehicleGeometry TestGeometry() {
  const pb::WorldDescription w = MakeWorld("test", kPi / 2);
  return viewer::GeometryFor(1, &w, nullptr);
}

// A state of the full model whose four wheels turn at `omega` rad/s, at step `step` (1 ms).
pb::VehicleState Spinning(std::uint64_t step, double omega) {
  TestVehicle t;
  t.step = step;
  pb::VehicleState s = MakeState(t);
  s.set_model(pb::VEHICLE_MODEL_FULL);
  for (int w = 0; w < 4; ++w) s.mutable_wheels(w)->set_omega(omega);
  return s;
}

// The angle a wheel instance's mark has turned from the wheel's forward (about its axle, positive
// rolling forward: the front of the wheel goes down).
double MarkAngle(const viewer::FrameLists& lists, const viewer::VehicleView& view, int wheel) {
  const viewer::WheelInstance& wi = lists.wheels.at(static_cast<std::size_t>(wheel));
  const viewer::WheelView& w = view.wheels[static_cast<std::size_t>(wheel)];
  const viewer::Vec3 up = viewer::Cross(w.forward_W, w.left_W);
  return std::atan2(-viewer::Dot(wi.R_WW.c[0], up), viewer::Dot(wi.R_WW.c[0], w.forward_W));
}

TEST(WheelSpin, TheRimTurnsByThePublishedWheelSpeedIntegratedOverSimulationTime) {
  const viewer::VehicleGeometry g = TestGeometry();
  viewer::WheelSpin spin;
  // The wheel speed rises linearly from 10 to 20 rad/s in 40 ms: the trapezoidal rule is exact,
  // the wheel turns (10 + 20) / 2 * 0.04 = 0.6 rad.
  viewer::AdvanceWheelSpin(spin, Spinning(100, 10));
  viewer::AdvanceWheelSpin(spin, Spinning(120, 15));
  viewer::AdvanceWheelSpin(spin, Spinning(140, 20));
  for (double a : spin.angle) EXPECT_NEAR(a, 0.6, 1e-9);
  // The same state again (a repeat) and an earlier one (a restore) turn nothing.
  viewer::AdvanceWheelSpin(spin, Spinning(140, 20));
  viewer::AdvanceWheelSpin(spin, Spinning(90, 20));
  for (double a : spin.angle) EXPECT_NEAR(a, 0.6, 1e-9);
  // ... and the next state after the restore turns from there: 20 rad/s for 10 ms.
  viewer::AdvanceWheelSpin(spin, Spinning(100, 20));
  for (double a : spin.angle) EXPECT_NEAR(a, 0.8, 1e-9);

  // The drawn wheel's mark (the rim and its tyre mark) is turned by that angle about the axle.
  const pb::VehicleState s = Spinning(100, 20);
  const viewer::VehicleView view = viewer::BuildVehicleView(s, g, &spin);
  viewer::FrameLists lists;
  viewer::AppendVehicleBody(view, viewer::VehicleParts{}, false, lists);
  ASSERT_EQ(lists.wheels.size(), 4u);
  for (int w = 0; w < 4; ++w) EXPECT_NEAR(MarkAngle(lists, view, w), 0.8, 1e-6) << "wheel " << w;
  // Not turned at all without a spin.
  const viewer::VehicleView still = viewer::BuildVehicleView(s, g, nullptr);
  viewer::FrameLists none;
  viewer::AppendVehicleBody(still, viewer::VehicleParts{}, false, none);
  for (int w = 0; w < 4; ++w) EXPECT_NEAR(MarkAngle(none, still, w), 0.0, 1e-9);
}

// --- the terrain's chunks ------------------------------------------------------------------------

// The ground's large tiles are split until no edge is longer than 16 m (chunks small enough to
// leave out of view and out of the shadow map) - but a huge plane (the server's `flat`: 40 km in
// 1 km tiles) stops splitting while it is still a mesh a viewer can hold: a 4 km plane in 1 km
// tiles, split to 16 m, would be 524,288 triangles.
TEST(TerrainChunks, LargeTilesAreSplitToChunksButAHugePlaneStaysBounded) {
  const viewer::TerrainData facility_like = viewer::TerrainFromWorld(MakeWorld("test", kPi / 2));
  int ground_meshes = 0;
  for (const viewer::TerrainMesh& m : facility_like.meshes) {
    if (m.style != viewer::SurfaceStyle::kGrass) continue;
    ++ground_meshes;
    EXPECT_GT(m.chunks.size(), 100u) << "400 m of ground in 32 m chunks";
    for (const viewer::TerrainChunk& c : m.chunks) {
      for (std::uint32_t k = 0; k + 2 < c.lods[0].count; k += 3) {
        const auto p = [&](std::uint32_t j) {
          const viewer::TerrainVertex& v = m.vertices[m.indices[c.lods[0].first + k + j]];
          return viewer::Vec3{v.p[0], v.p[1], v.p[2]};
        };
        const double longest = std::max(
            {viewer::Norm(p(0) - p(1)), viewer::Norm(p(1) - p(2)), viewer::Norm(p(2) - p(0))});
        ASSERT_LE(longest, 16.0 + 1e-3);
      }
    }
  }
  EXPECT_EQ(ground_meshes, 1);

  pb::WorldDescription huge;
  huge.set_name("huge_flat");
  pb::Mesh* g = huge.add_meshes();
  g->set_name("ground");
  g->set_kind(pb::SURFACE_GROUND);
  for (int i = -2; i < 2; ++i) {
    for (int j = -2; j < 2; ++j) {
      const auto base = static_cast<std::uint32_t>(g->vertices_size() / 3);
      for (auto [x, y] : {std::pair{i, j}, {i + 1, j}, {i + 1, j + 1}, {i, j + 1}}) {
        g->add_vertices(1000.0 * x);
        g->add_vertices(1000.0 * y);
        g->add_vertices(0.0);
      }
      for (std::uint32_t k : {0u, 1u, 2u, 0u, 2u, 3u}) g->add_indices(base + k);
    }
  }
  ASSERT_EQ(viewer::CheckWorld(huge), "");
  const viewer::TerrainData t = viewer::TerrainFromWorld(huge);
  ASSERT_EQ(t.meshes.size(), 1u);
  std::size_t finest = 0;  // the full-detail level's triangles (coarser levels come after them)
  for (const viewer::TerrainChunk& c : t.meshes[0].chunks) finest += c.lods[0].count / 3;
  EXPECT_LE(finest, 262144u);
  EXPECT_GE(finest, 32u * 64u) << "not split at all";
  EXPECT_NEAR(t.min_W.x, -2000, 1e-6);
  EXPECT_NEAR(t.max_W.y, 2000, 1e-6);

  // A vertex the server's terrain would never hold (beyond 1e9 m, or not finite) is refused with
  // where it is, before anything converts it (issue 33: 1e30 overflowed the grid's cell index).
  for (double bad : {1e30, -2e9, std::numeric_limits<double>::quiet_NaN()}) {
    pb::WorldDescription far = huge;
    far.mutable_meshes(0)->set_vertices(4, bad);
    EXPECT_NE(viewer::CheckWorld(far).find(
                  "mesh 'ground' (0): vertex 1: terrain vertex coordinate, m must be"),
              std::string::npos)
        << bad << ": " << viewer::CheckWorld(far);
  }
}

// --- a car model from a file -------------------------------------------------------------------

TEST(CarModel, AFilesBodyIsReadInBodyAxesWithoutItsWheelsAndBrokenFilesSayWhy) {
  TempDir dir;
  // A box 4 m long along +Z (forward), 1.8 m wide along X, 1.2 m tall along +Y (up), and a
  // wheel node: OBJ, as a modeller writes it (+Y up).
  const auto box = dir.path() / "car.obj";
  {
    std::ofstream f(box);
    f << "o body\n";
    for (int i = 0; i < 8; ++i) {
      f << "v " << ((i & 1) ? 0.9 : -0.9) << " " << ((i & 2) ? 1.2 : 0.0) << " "
        << ((i & 4) ? 2.0 : -2.0) << "\n";
    }
    // Six faces of two triangles (vertices 1-based: bit 0 x, bit 1 y, bit 2 z).
    f << "f 1 3 4\nf 1 4 2\nf 5 6 8\nf 5 8 7\nf 1 2 6\nf 1 6 5\n"
         "f 3 7 8\nf 3 8 4\nf 1 5 7\nf 1 7 3\nf 2 4 8\nf 2 8 6\n";
    f << "o wheel_front_left\nv 0.9 -0.3 1.5\nv 1.2 -0.3 1.5\nv 0.9 0.3 1.8\nf 9 10 11\n";
  }
  const viewer::ModelMesh m = viewer::LoadCarModel(box.string());
  EXPECT_EQ(m.triangles(), 12u) << "the wheel's triangle is the viewer's to draw";
  // Body axes: X forward (the file's +Z), Y left (+X), Z up (+Y); the fit counts the wheel.
  EXPECT_NEAR(m.fit_min.x, -2.0, 1e-6);
  EXPECT_NEAR(m.fit_max.x, 2.0, 1e-6);
  EXPECT_NEAR(m.fit_max.y, 1.2, 1e-6);
  EXPECT_NEAR(m.fit_min.z, -0.3, 1e-6);
  EXPECT_NEAR(m.max.z, 1.2, 1e-6);
  // Fitted to a vehicle: its length the body box's (front + rear), its lowest point the ground.
  const viewer::VehicleGeometry g = TestGeometry();
  const viewer::Mat4 fit = viewer::FitModel(m, g, false);
  const viewer::CarShape shape = viewer::CarShapeFor(g);
  EXPECT_NEAR(fit.TransformPoint({-2, 0, 0}).x, -TestCar::kRear, 1e-6);
  EXPECT_NEAR(fit.TransformPoint({2, 0, 0}).x, TestCar::kFront, 1e-6);
  EXPECT_NEAR(fit.TransformPoint({0, 0, -0.3}).z, shape.z_ground, 1e-6);

  const auto expect_error = [&](const std::filesystem::path& path, const std::string& why) {
    try {
      viewer::LoadCarModel(path.string());
      ADD_FAILURE() << path << " was read";
    } catch (const viewer::CarModelError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(path.string()), std::string::npos) << what;
      EXPECT_NE(what.find(why), std::string::npos) << what;
    }
  };
  expect_error(dir.path() / "missing.glb", "");
  {
    std::ofstream f(dir.path() / "garbage.glb", std::ios::binary);
    f << "glTF\x02\x00\x00\x00 this is not a model";
  }
  expect_error(dir.path() / "garbage.glb", "");
  {
    std::ofstream f(dir.path() / "wheels.obj");
    f << "o wheel\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  }
  expect_error(dir.path() / "wheels.obj", "holds no triangle");
  {
    std::ofstream f(dir.path() / "flat.obj");
    f << "o body\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";  // no length along +Z
  }
  expect_error(dir.path() / "flat.obj", "no length along +Z");
}

// --- the parameters panel --------------------------------------------------------------------

TEST(ParamsEditorChanges, OnlyTheChangedFieldsAreSent) {
  pb::VehicleParams current;
  current.set_mass(1500);
  current.set_mu(0.9);
  current.mutable_lf()->set_radius(0.32);
  current.mutable_rf()->set_radius(0.32);
  pb::VehicleParams edited = current;
  EXPECT_EQ(viewer::ParamsEditor::Changes(current, edited).ByteSizeLong(), 0u);
  edited.set_mass(1600);
  edited.mutable_rf()->set_radius(0.33);
  const pb::VehicleParams c = viewer::ParamsEditor::Changes(current, edited);
  EXPECT_TRUE(c.has_mass());
  EXPECT_EQ(c.mass(), 1600);
  EXPECT_FALSE(c.has_mu());
  EXPECT_FALSE(c.has_lf());
  ASSERT_TRUE(c.has_rf());
  EXPECT_EQ(c.rf().radius(), 0.33);
}

// The panel's first request to a server follows that server's answer to a hello (a request
// written before the server has discovered the viewer's writer reaches no one); later requests
// to it go at once.
TEST(ParamsEditorRequests, TheFirstRequestToAServerFollowsItsAnswerToAHello) {
  const std::uint32_t domain = FreshDomain();
  transport::Participant viewer_side(domain);
  viewer::ParamsEditor editor(viewer_side, "panel");
  transport::Participant server_side(domain);
  AnsweringPeer server(server_side, "fake");
  using State = viewer::ParamsEditor::Status::State;
  auto set_params_seen = [&] {
    int n = 0;
    for (const pb::ControlRequest& r : server.seen) n += r.has_set_params();
    return n;
  };
  pb::VehicleParams change;
  change.set_mass(1600);
  ASSERT_TRUE(editor.Submit(1, "fake", change));
  ASSERT_TRUE(server.ServeUntil(std::chrono::seconds(30),
                                [&] { return editor.status().state != State::kPending; }));
  EXPECT_EQ(editor.status().state, State::kAccepted) << editor.status().text;
  ASSERT_EQ(set_params_seen(), 1);
  ASSERT_GE(server.seen.size(), 2u);
  EXPECT_TRUE(server.seen.front().has_hello());
  EXPECT_EQ(server.seen.front().server_id(), "fake");
  EXPECT_TRUE(server.seen.back().has_set_params());
  EXPECT_EQ(server.seen.back().set_params().params().mass(), 1600);

  const std::size_t before = server.seen.size();
  change.set_mass(1700);
  ASSERT_TRUE(editor.Submit(1, "fake", change));
  ASSERT_TRUE(server.ServeUntil(std::chrono::seconds(30),
                                [&] { return editor.status().state != State::kPending; }));
  EXPECT_EQ(editor.status().state, State::kAccepted) << editor.status().text;
  ASSERT_EQ(server.seen.size(), before + 1) << "no second hello to a server that answered one";
  EXPECT_TRUE(server.seen.back().has_set_params());
}

}  // namespace
}  // namespace vdyn::testing

namespace vdyn::testing {
namespace {

TEST(ViewerCulling, SpheresOutsideTheViewAreLeftOut) {
  using viewer::Vec3;
  // A camera at the origin looking along +X, 60 deg tall, 4:3, seeing 0.2 .. 1000 m.
  const viewer::Mat4 vp = viewer::Perspective(viewer::Rad(60), 4.0 / 3.0, 0.2, 1000) *
                          viewer::LookAt({0, 0, 0}, {1, 0, 0}, {0, 0, 1});
  EXPECT_TRUE(viewer::InFrustum(vp, {50, 0, 0}, 1));
  EXPECT_FALSE(viewer::InFrustum(vp, {-50, 0, 0}, 1));   // behind
  EXPECT_FALSE(viewer::InFrustum(vp, {50, 60, 0}, 1));   // far to the left (half-width 38 m)
  EXPECT_TRUE(viewer::InFrustum(vp, {50, 60, 0}, 25));   // ... unless it reaches into view
  EXPECT_FALSE(viewer::InFrustum(vp, {2000, 0, 0}, 1));  // beyond the far plane
  EXPECT_TRUE(viewer::InFrustum(vp, {50, 0, 28}, 1));    // just under the top (28.9 m)
  EXPECT_FALSE(viewer::InFrustum(vp, {50, 0, 31}, 1));
}

// The dressing around the facility (trees, buildings, signs, hills) stands only where no vehicle
// can drive: every triangle's bounds are checked against the facility's description as its
// server publishes it - the glass barrier's bounds (which keep every vehicle in) and each mesh a
// vehicle drives on - not against the numbers the dressing was placed by. Worlds a vehicle is not
// closed in get none.
TEST(Dressing, NothingStandsWhereAVehicleCanDriveAndAnOpenWorldGetsNone) {
  const std::unique_ptr<World> world = BuildBuiltinWorld("facility");
  const pb::WorldDescription w = DescribeWorld(*world, "test", 1'000'000);
  struct Box {
    double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
    void Add(double x, double y) {
      x0 = std::min(x0, x);
      y0 = std::min(y0, y);
      x1 = std::max(x1, x);
      y1 = std::max(y1, y);
    }
    bool Overlaps(const Box& o, double margin) const {
      return x0 < o.x1 + margin && o.x0 - margin < x1 && y0 < o.y1 + margin && o.y0 - margin < y1;
    }
  };
  Box barrier;
  std::vector<std::pair<std::string, Box>> drivable;
  for (const pb::Mesh& m : w.meshes()) {
    Box b;
    for (int i = 0; i + 2 < m.vertices_size(); i += 3) b.Add(m.vertices(i), m.vertices(i + 1));
    if (m.kind() == pb::SURFACE_BARRIER) {
      barrier.Add(b.x0, b.y0);
      barrier.Add(b.x1, b.y1);
    } else if (m.kind() != pb::SURFACE_GROUND) {
      drivable.emplace_back(m.name(), b);
    }
  }
  ASSERT_GT(barrier.x1 - barrier.x0, 100.0);
  ASSERT_GE(drivable.size(), 5u);
  for (bool full : {true, false}) {
    const viewer::Dressing d = viewer::MakeDressing(viewer::TerrainFromWorld(w), full);
    ASSERT_TRUE(d.enclosed) << "the facility's barrier closes it in";
    EXPECT_GT(d.trees, full ? 150u : 40u);
    const auto& v = d.list.vertices();
    ASSERT_GT(v.size(), 3000u);
    std::size_t inside = 0, on_drivable = 0, near_barrier = 0;
    std::string first;
    for (std::size_t k = 0; k + 2 < v.size(); k += 3) {
      Box t;
      for (std::size_t q = 0; q < 3; ++q) t.Add(v[k + q].p[0], v[k + q].p[1]);
      if (t.Overlaps(barrier, 1.0)) {
        if (inside++ == 0) first = std::to_string(t.x0) + ", " + std::to_string(t.y0);
      }
      for (const auto& [name, b] : drivable) on_drivable += t.Overlaps(b, 1.0) ? 1 : 0;
      // (Some of it near the barrier: the place is dressed, not only its horizon.)
      near_barrier += t.Overlaps(barrier, 30.0) ? 1 : 0;
    }
    EXPECT_EQ(inside, 0u) << "triangles within 1 m of the barrier's bounds; the first at " << first;
    EXPECT_EQ(on_drivable, 0u);
    EXPECT_GT(near_barrier, 500u);
  }
  // An open world (a road on open ground, no barrier) gets no dressing.
  const viewer::Dressing open =
      viewer::MakeDressing(viewer::TerrainFromWorld(MakeWorld("test", 0)), true);
  EXPECT_FALSE(open.enclosed);
  EXPECT_TRUE(open.list.vertices().empty());
  // Nor does the facility with a gap in its barrier: the north wall's triangles left out.
  pb::WorldDescription gap = w;
  for (pb::Mesh& m : *gap.mutable_meshes()) {
    if (m.kind() != pb::SURFACE_BARRIER) continue;
    google::protobuf::RepeatedField<std::uint32_t> kept;
    for (int i = 0; i + 2 < m.indices_size(); i += 3) {
      bool north = true;
      for (int q = 0; q < 3; ++q)
        north = north && m.vertices(3 * static_cast<int>(m.indices(i + q)) + 1) > 0.9 * barrier.y1;
      if (north) continue;
      for (int q = 0; q < 3; ++q) kept.Add(m.indices(i + q));
    }
    ASSERT_LT(kept.size(), m.indices_size());
    *m.mutable_indices() = kept;
  }
  EXPECT_FALSE(viewer::MakeDressing(viewer::TerrainFromWorld(gap), true).enclosed);
  // A barrier 20,000 km a side (coordinates within the description's bound) closes in the road,
  // but gets no dressing: the work would grow with its length.
  pb::WorldDescription huge = MakeWorld("test", 0);
  pb::Mesh* wall = huge.add_meshes();
  wall->set_name("far_barrier");
  wall->set_kind(pb::SURFACE_BARRIER);
  const double r = 1e7;
  const double corners[5][2] = {{-r, -r}, {r, -r}, {r, r}, {-r, r}, {-r, -r}};
  for (int k = 0; k < 4; ++k) {
    const auto base = static_cast<std::uint32_t>(wall->vertices_size() / 3);
    for (const double* c : {corners[k], corners[k + 1]}) {
      for (double z : {0.0, 1.5}) {
        wall->add_vertices(c[0]);
        wall->add_vertices(c[1]);
        wall->add_vertices(z);
      }
    }
    for (std::uint32_t i : {0u, 2u, 3u, 0u, 3u, 1u}) wall->add_indices(base + i);
  }
  const viewer::TerrainData huge_t = viewer::TerrainFromWorld(huge);
  viewer::Vec3 lo, hi;
  ASSERT_TRUE(viewer::BarrierEncloses(huge_t, &lo, &hi));
  EXPECT_TRUE(viewer::MakeDressing(huge_t, true).list.vertices().empty());
}

// The facility's billboard gets its poster on the panel's face towards the facility (south): 9 m
// wide, 3 m high, its lower left corner (seen from the front) at the panel's west end, 3 m up.
TEST(Poster, TheBillboardsPanelFacingTheFacilityCarriesIt) {
  const std::unique_ptr<World> world = BuildBuiltinWorld("facility");
  const viewer::TerrainData t = viewer::TerrainFromWorld(DescribeWorld(*world, "test", 1'000'000));
  const viewer::TerrainMesh* board = nullptr;
  for (const viewer::TerrainMesh& m : t.meshes) {
    if (m.name == "billboard") board = &m;
    if (m.name != "billboard") {
      EXPECT_FALSE(m.poster.present) << m.name;
    }
  }
  ASSERT_NE(board, nullptr);
  const viewer::PosterFace& f = board->poster;
  ASSERT_TRUE(f.present);
  EXPECT_NEAR(f.width_m, 9.0, 1e-3);
  EXPECT_NEAR(f.height_m, 3.0, 1e-3);
  EXPECT_NEAR(f.right_W.x, 1.0, 1e-6);  // seen from the south, east is to the right
  EXPECT_NEAR(f.origin_W.x, -4.5, 1e-3);
  EXPECT_NEAR(f.origin_W.y, 170.0, 1e-3);
  EXPECT_NEAR(f.origin_W.z, 3.0, 1e-3);
}

// The sRGB curve (IEC 61966-2-1) as the standard writes it; the viewer answers from tables.
double SrgbDecodeFormula(int byte) {
  const double c = byte / 255.0;
  return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}
int SrgbEncodeFormula(double linear) {
  const double c = std::clamp(linear, 0.0, 1.0);
  const double v = c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055;
  return static_cast<int>(std::lround(v * 255.0));
}

// ToLinear and ToSrgb give the curve's own answers: every byte decoded, a million evenly spaced
// linear values and each byte's edges (the values around where the encoding steps up) encoded,
// out-of-range values clamped, a NaN black.
TEST(ViewerColour, TheSrgbTablesAnswerAsTheCurve) {
  for (int b = 0; b < 256; ++b) {
    ASSERT_EQ(viewer::ToLinear(static_cast<std::uint8_t>(b)), SrgbDecodeFormula(b)) << b;
    ASSERT_EQ(viewer::ToSrgb(SrgbDecodeFormula(b)), b) << b;  // each byte comes back
  }
  for (int i = 0; i <= 1'000'000; ++i) {
    const double x = i / 1e6;
    ASSERT_EQ(viewer::ToSrgb(x), SrgbEncodeFormula(x)) << x;
  }
  for (int k = 1; k < 256; ++k) {  // the edge between k - 1 and k, to the last double
    double lo = 0, hi = 1;
    for (int it = 0; it < 200 && std::nextafter(lo, 1.0) < hi; ++it) {
      const double mid = lo + (hi - lo) / 2;
      (SrgbEncodeFormula(mid) >= k ? hi : lo) = mid;
    }
    for (const double x : {std::nextafter(lo, 0.0), lo, hi, std::nextafter(hi, 1.0)}) {
      ASSERT_EQ(viewer::ToSrgb(x), SrgbEncodeFormula(x)) << "byte " << k << " at " << x;
    }
  }
  EXPECT_EQ(viewer::ToSrgb(-0.5), 0);
  EXPECT_EQ(viewer::ToSrgb(7.0), 255);
  EXPECT_EQ(viewer::ToSrgb(std::numeric_limits<double>::quiet_NaN()), 0);
  EXPECT_EQ(viewer::ToSrgb(std::numeric_limits<double>::infinity()), 255);
}

}  // namespace
}  // namespace vdyn::testing
