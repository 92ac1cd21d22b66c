#include "vdyn/viewer/cockpit.h"

#include <algorithm>
#include <cmath>

#include "vdyn/viewer/car_model.h"
#include "vdyn/viewer/draw_list.h"

namespace vdyn::viewer {
namespace {

constexpr Rgb8 kDash{58, 58, 62};
constexpr Rgb8 kTrimDark{48, 48, 52};
constexpr Rgb8 kLining{172, 168, 158};
constexpr Rgb8 kDoor{50, 50, 54};
constexpr Rgb8 kFloor{26, 26, 28};
constexpr Rgb8 kWheelRim{36, 36, 40};
constexpr Rgb8 kWheelSpoke{62, 62, 68};
constexpr Rgb8 kDialFace{14, 14, 16};
constexpr Rgb8 kBezel{150, 150, 156};
constexpr Rgb8 kTick{228, 228, 228};
constexpr Rgb8 kRedline{215, 30, 30};
constexpr Rgb8 kSegmentOn{250, 250, 250};
constexpr Rgb8 kSegmentOff{34, 34, 37};
constexpr Rgb8 kMirrorHousing{30, 30, 33};
const Vec3 kUnlit{0, 0, 0};

// Triangles in the body frame, drawn in the world at the vehicle's pose.
struct Painter {
  const Pose& pose;
  DrawList& list;
  void Tri(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& n_B, Rgb8 col) {
    const Vec3 n = Norm(n_B) > 0 ? pose.R * n_B : kUnlit;
    list.Triangle(pose * a, pose * b, pose * c, n, col);
  }
  void Quad(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d, const Vec3& n_B, Rgb8 col) {
    Tri(a, b, c, n_B, col);
    Tri(a, c, d, n_B, col);
  }
  // A flat ring (or disc: r0 = 0) about `centre` in the plane of u and w.
  void Ring(const Vec3& centre, const Vec3& u, const Vec3& w, double r0, double r1, const Vec3& n,
            Rgb8 col, int segments = 32) {
    for (int i = 0; i < segments; ++i) {
      const double a0 = 2 * kPi * i / segments, a1 = 2 * kPi * (i + 1) / segments;
      const Vec3 d0 = u * std::cos(a0) + w * std::sin(a0), d1 = u * std::cos(a1) + w * std::sin(a1);
      if (r0 <= 0) {
        Tri(centre, centre + d0 * r1, centre + d1 * r1, n, col);
      } else {
        Quad(centre + d0 * r0, centre + d0 * r1, centre + d1 * r1, centre + d1 * r0, n, col);
      }
    }
  }
  // A bar from a to b, its width going from width_a to width_b, in the plane with normal n (a
  // needle, a tick, a segment); unlit unless `lit`.
  void Bar(const Vec3& a, const Vec3& b, double width_a, double width_b, const Vec3& n, Rgb8 col,
           bool lit = false) {
    const Vec3 side = Normalized(Cross(n, b - a), Vec3{0, 1, 0});
    Quad(a - side * (0.5 * width_a), b - side * (0.5 * width_b), b + side * (0.5 * width_b),
         a + side * (0.5 * width_a), lit ? n : kUnlit, col);
  }
  void Box(const Vec3& mn, const Vec3& mx, Rgb8 col) { list.Box(pose, mn, mx, col); }
};

// A dial: its face, bezel, ticks (major every `major`, minor between), the red zone from
// `redline` to full scale, and the needle at `value`.
void Dial(Painter& p, const Vec3& centre, const Vec3& n, double radius, double full_scale,
          double major, double redline, double value) {
  const Vec3 up = Normalized(Vec3{0, 0, 1} - n * Dot(Vec3{0, 0, 1}, n), Vec3{0, 0, 1});
  const Vec3 right = Cross(up, n);  // the driver's right on the dial
  auto dir = [&](double angle) { return up * std::cos(angle) + right * std::sin(angle); };
  p.Ring(centre, up, right, 0, radius, kUnlit, kDialFace);
  p.Ring(centre - n * 0.002, up, right, radius, 1.12 * radius, n, kBezel);
  const Vec3 face = centre + n * 0.001;
  for (double v = 0; v <= full_scale + 1e-9; v += 0.5 * major) {
    const bool is_major = std::fmod(v + 1e-9, major) < 1e-6;
    const Vec3 d = dir(DialAngle(v, full_scale));
    p.Bar(face + d * (radius * (is_major ? 0.74 : 0.84)), face + d * (radius * 0.94), radius * 0.07,
          radius * 0.07, n, v >= redline ? kRedline : kTick);
  }
  const Vec3 needle = centre + n * 0.002, d = dir(DialAngle(value, full_scale));
  p.Bar(needle - d * (0.12 * radius), needle + d * (0.9 * radius), 0.13 * radius, 0.06 * radius, n,
        kNeedleColour);
  p.Ring(centre + n * 0.003, up, right, 0, 0.16 * radius, kUnlit, kNeedleHubColour, 16);
}

// The engaged gear as a seven-segment digit ('r' reverse, 'n' neutral; dark without a gearbox).
void GearDigit(Painter& p, const Vec3& centre, const Vec3& n, double height, const VehicleView& v) {
  //  segments: a top, b upper right, c lower right, d bottom, e lower left, f upper left, g middle
  static constexpr unsigned kDigits[10] = {0x3F, 0x06, 0x5B, 0x4F, 0x66,
                                           0x6D, 0x7D, 0x07, 0x7F, 0x6F};
  unsigned lit = 0;
  if (v.has_gearbox) {
    if (v.gear < 0) {
      lit = 0x50;  // r: e, g
    } else if (v.gear == 0) {
      lit = 0x54;  // n: c, e, g
    } else {
      lit = kDigits[std::min(v.gear, 9)];
    }
  }
  const Vec3 up = Normalized(Vec3{0, 0, 1} - n * Dot(Vec3{0, 0, 1}, n), Vec3{0, 0, 1});
  const Vec3 right = Cross(up, n);
  const double h = 0.5 * height, w = 0.28 * height, t = 0.12 * height;
  const Vec3 c = centre + n * 0.002;
  auto at = [&](double x, double y) { return c + right * x + up * y; };
  struct Segment {
    double x0, y0, x1, y1;
  };
  const Segment segments[7] = {{-w, h, w, h},   {w, h, w, 0},   {w, 0, w, -h}, {-w, -h, w, -h},
                               {-w, 0, -w, -h}, {-w, h, -w, 0}, {-w, 0, w, 0}};
  p.Ring(centre, up, right, 0, 0.8 * height, kUnlit, kDialFace, 16);
  for (int i = 0; i < 7; ++i) {
    const Segment& s = segments[i];
    p.Bar(at(s.x0, s.y0), at(s.x1, s.y1), t, t, n, (lit >> i) & 1U ? kSegmentOn : kSegmentOff);
  }
}

// The steering wheel turned by the hand-wheel angle (positive left: counter-clockwise as the
// driver sees it): a rim with a mark at its top, three spokes, the hub and the column.
void SteeringWheel(Painter& p, const CockpitLayout& l, double angle) {
  const Vec3 n = l.wheel_normal_B, c = l.wheel_centre_B;
  const Vec3 left0 = Cross(n, l.wheel_up_B);  // the wheel's left before it turns
  const Vec3 up = l.wheel_up_B * std::cos(angle) + left0 * std::sin(angle);
  const Vec3 left = left0 * std::cos(angle) - l.wheel_up_B * std::sin(angle);
  const double R = l.wheel_radius, tube = 0.016;
  constexpr int kAround = 40, kTube = 6;
  for (int i = 0; i < kAround; ++i) {
    const double a0 = 2 * kPi * i / kAround, a1 = 2 * kPi * (i + 1) / kAround;
    const double mid = WrapAngle(0.5 * (a0 + a1));
    const Rgb8 col = std::abs(mid) < Rad(8) ? kWheelMarkColour : kWheelRim;
    const Vec3 u0 = up * std::cos(a0) + left * std::sin(a0);
    const Vec3 u1 = up * std::cos(a1) + left * std::sin(a1);
    for (int j = 0; j < kTube; ++j) {
      const double b0 = 2 * kPi * j / kTube, b1 = 2 * kPi * (j + 1) / kTube;
      auto pt = [&](const Vec3& u, double b) {
        return c + u * (R + tube * std::cos(b)) + n * (tube * std::sin(b));
      };
      const Vec3 normal =
          Normalized(u0 + u1) * std::cos(0.5 * (b0 + b1)) + n * std::sin(0.5 * (b0 + b1));
      p.Quad(pt(u0, b0), pt(u1, b0), pt(u1, b1), pt(u0, b1), normal, col);
    }
  }
  for (const Vec3& d : {left, -left, -up}) {
    p.Bar(c + d * 0.045 - n * 0.006, c + d * (R - 0.01) - n * 0.006, 0.05, 0.034, n, kWheelSpoke,
          true);
  }
  p.Ring(c + n * 0.004, up, left, 0, 0.06, n, kWheelSpoke, 20);
  p.list.Cylinder(p.pose * (c - n * 0.01), p.pose * (c - n * 0.32), 0.03, kTrimDark, true, 10);
}

// The mirrors' housings: a shell behind each glass, a little larger; the rear-view mirror's stem
// up to the windscreen, the side mirrors' arms into the doors.
void MirrorHousings(Painter& p, const std::array<Mirror, kMirrors>& mirrors, const Cabin& cab) {
  for (int i = 0; i < kMirrors; ++i) {
    const Mirror& m = mirrors[static_cast<std::size_t>(i)];
    const Vec3 back = -m.normal_B;
    const double w = m.half_width + 0.012, h = m.half_height + 0.012, depth = 0.035;
    auto at = [&](double x, double y, double d) {
      return m.centre_B + m.right_B * x + m.up_B * y + back * d;
    };
    // The rim around the glass (its face towards the eyes) and the shell's back and sides.
    p.Quad(at(-w, -h, 0), at(w, -h, 0), at(w, h, 0), at(-w, h, 0), m.normal_B, kMirrorHousing);
    p.Quad(at(-w, -h, depth), at(-w, h, depth), at(w, h, depth), at(w, -h, depth), back,
           kMirrorHousing);
    p.Quad(at(-w, h, 0), at(w, h, 0), at(w, h, depth), at(-w, h, depth), m.up_B, kMirrorHousing);
    p.Quad(at(-w, -h, 0), at(-w, -h, depth), at(w, -h, depth), at(w, -h, 0), -m.up_B,
           kMirrorHousing);
    p.Quad(at(w, -h, 0), at(w, -h, depth), at(w, h, depth), at(w, h, 0), -m.right_B,
           kMirrorHousing);
    p.Quad(at(-w, -h, 0), at(-w, h, 0), at(-w, h, depth), at(-w, -h, depth), m.right_B,
           kMirrorHousing);
    if (i == kRearViewMirror) {
      const Vec3 top = at(0, h, 0.5 * depth);
      p.list.Cylinder(p.pose * top, p.pose * (top + Vec3{0.06, 0, 0.06}), 0.008, kTrimDark, true,
                      6);
    } else {
      const double side = m.centre_B.y > 0 ? 1.0 : -1.0;
      const Vec3 base = at(side * 0.5 * w, -0.3 * h, depth);
      p.list.Cylinder(p.pose * base, p.pose * Vec3{base.x, side * 0.93 * cab.half_width, base.z},
                      0.015, kMirrorHousing, true, 6);
    }
  }
}

}  // namespace

double DialAngle(double value, double full_scale) {
  const double u = std::clamp(value / std::max(full_scale, 1e-9), 0.0, 1.0);
  return Rad(-0.5 * kDialSweepDeg + kDialSweepDeg * u);
}

double TachoFullScaleRpm(const VehicleGeometry& g) {
  return 1000.0 * std::ceil(g.engine_rpm_limit / 1000.0 - 1e-9) + 1000.0;
}

CockpitLayout CockpitFor(const VehicleGeometry& g, const Vec3& seat_B) {
  const Cabin cab = CabinFor(g);
  CockpitLayout l;
  // The wheel 0.5 m ahead of the eyes and 0.32 m below, its plane leaning back 22 deg from the
  // vertical; the dials 0.66 m ahead, either side of the column, facing the eyes, under the
  // dashboard's top (the windscreen's base: it never rises into the view of the road).
  const double lean = Rad(22);
  l.wheel_centre_B = seat_B + Vec3{0.50, 0, -0.32};
  l.wheel_normal_B = {-std::cos(lean), 0, std::sin(lean)};
  l.wheel_up_B = {std::sin(lean), 0, std::cos(lean)};
  const double dash_top = std::min(cab.z_belt_cowl, seat_B.z - 0.12);
  const double x_gauges = seat_B.x + 0.66;
  const double z_gauges = dash_top - 0.085;
  l.speedo_B = {x_gauges, seat_B.y + 0.092, z_gauges};
  l.tacho_B = {x_gauges, seat_B.y - 0.092, z_gauges};
  l.gear_B = {x_gauges, seat_B.y, z_gauges + 0.01};
  l.gauge_normal_B = Normalized(seat_B - Vec3{x_gauges, seat_B.y, z_gauges});
  return l;
}

std::array<Mirror, kMirrors> MirrorsFor(const VehicleGeometry& g, const Vec3& seat_B) {
  const Cabin cab = CabinFor(g);
  // The windscreen's inner face: x where it is at height z (from the cowl to the roof's front).
  const double rise = std::max(cab.z_roof_front - cab.z_belt_cowl, 0.1);
  auto x_glass = [&](double z) {
    return cab.x_cowl + (z - cab.z_belt_cowl) / rise * (cab.x_roof_front - cab.x_cowl);
  };
  std::array<Mirror, kMirrors> m;
  // The rear-view mirror hangs from the windscreen a little above the eyes, 5 cm behind the
  // glass, a third of the way from the centre line towards the driver (so a 16:9 driver camera
  // sees it whole); 20 x 7 cm. The side mirrors stand out of the doors' front ends above the
  // belt line, 18 x 12 cm.
  m[kRearViewMirror].half_width = 0.10;
  m[kRearViewMirror].half_height = 0.035;
  const double z_rear = seat_B.z + 0.05;
  m[kRearViewMirror].centre_B = {std::max(x_glass(z_rear + 0.035) - 0.05, seat_B.x + 0.3),
                                 seat_B.y / 3, z_rear};
  m[kRearViewMirror].look_B = {-1, 0, 0};
  for (int i : {kLeftMirror, kRightMirror}) {
    const double side = i == kLeftMirror ? 1.0 : -1.0;
    Mirror& s = m[static_cast<std::size_t>(i)];
    s.half_width = 0.09;
    s.half_height = 0.06;
    s.centre_B = {cab.x_cowl - 0.1, side * (cab.half_width + 0.1), cab.z_belt_cowl + 0.08};
    s.look_B = Normalized(Vec3{-1, side * 0.15, 0});
  }
  for (Mirror& mi : m) {
    // The glass's normal halves the angle between the sight line (reversed) and the look.
    const Vec3 sight = Normalized(mi.centre_B - seat_B);
    mi.normal_B = Normalized(mi.look_B - sight);
    mi.up_B = Normalized(Vec3{0, 0, 1} - mi.normal_B * mi.normal_B.z, Vec3{0, 0, 1});
    mi.right_B = Cross(-mi.normal_B, mi.up_B);
  }
  return m;
}

void AppendMirrors(const VehicleView& v, const Vec3& seat_B, std::vector<MirrorInstance>& out) {
  const Pose& pose = v.pose_WB;
  const auto mirrors = MirrorsFor(v.geometry, seat_B);
  for (int i = 0; i < kMirrors; ++i) {
    const Mirror& m = mirrors[static_cast<std::size_t>(i)];
    MirrorInstance mi;
    mi.index = i;
    mi.eye_W = pose * m.centre_B;
    mi.look_W = pose.R * m.look_B;
    mi.up_W = pose.R * Vec3{0, 0, 1};
    // The image's axes: looking along `look`, its right and up.
    const Vec3 f = m.look_B, r = Normalized(Cross(f, Vec3{0, 0, 1})), u = Cross(r, f);
    std::array<std::array<double, 2>, 4> t{};
    mi.tan_half_x = mi.tan_half_y = 1e-3;
    const double sx[4] = {-1, 1, 1, -1}, sy[4] = {-1, -1, 1, 1};
    for (std::size_t k = 0; k < 4; ++k) {
      // The glass in front of the housing; each corner's line of sight reflected by it.
      const Vec3 c = m.centre_B + m.normal_B * 0.004 + m.right_B * (sx[k] * m.half_width) +
                     m.up_B * (sy[k] * m.half_height);
      mi.glass_W[k] = pose * c;
      const Vec3 d = Normalized(c - seat_B);
      const Vec3 refl = d - m.normal_B * (2 * Dot(d, m.normal_B));
      const double along = std::max(Dot(refl, f), 1e-3);
      t[k] = {Dot(refl, r) / along, Dot(refl, u) / along};
      mi.tan_half_x = std::max(mi.tan_half_x, std::abs(t[k][0]));
      mi.tan_half_y = std::max(mi.tan_half_y, std::abs(t[k][1]));
    }
    for (std::size_t k = 0; k < 4; ++k) {
      mi.uv[k] = {static_cast<float>(0.5 + 0.5 * t[k][0] / mi.tan_half_x),
                  static_cast<float>(0.5 + 0.5 * t[k][1] / mi.tan_half_y)};
    }
    out.push_back(mi);
  }
}

Mat4 MirrorViewProj(const MirrorInstance& m, double far_m) {
  return Perspective(2 * std::atan(m.tan_half_y), m.tan_half_x / m.tan_half_y, 0.05, far_m) *
         LookAt(m.eye_W, m.eye_W + m.look_W, m.up_W);
}

void AppendCockpit(const VehicleView& v, const Vec3& seat_B, DrawList& list) {
  const VehicleGeometry& g = v.geometry;
  const Cabin cab = CabinFor(g);
  const CockpitLayout l = CockpitFor(g, seat_B);
  Painter p{v.pose_WB, list};
  const double hw = cab.half_width;
  const double dash_top = std::min(cab.z_belt_cowl, seat_B.z - 0.12);
  // The dashboard's face towards the driver, behind the dials' tops (they lean back to face
  // the eyes).
  const double x_dash = l.speedo_B.x + 0.5 * l.gauge_radius + 0.01;
  const double x_cowl = std::max(cab.x_cowl, x_dash + 0.1);
  // The dashboard, the binnacle's hood over the dials.
  // The floor (the body's underside is culled from inside: the road would show through) and
  // the dashboard down to it.
  const double z_floor = cab.H(0.30);
  p.Box({seat_B.x - 0.8, -0.93 * hw, z_floor - 0.02}, {x_cowl, 0.93 * hw, z_floor}, kFloor);
  p.Box({x_dash, -0.95 * hw, z_floor}, {x_cowl, 0.95 * hw, dash_top}, kDash);
  p.Box({x_dash - 0.05, seat_B.y - 0.21, dash_top - 0.005},
        {x_dash + 0.12, seat_B.y + 0.21, dash_top + 0.03}, kDash);
  // The dials and the gear between them.
  Dial(p, l.speedo_B, l.gauge_normal_B, l.gauge_radius, kSpeedoFullScaleKmh, 20,
       kSpeedoFullScaleKmh + 1, v.speed_kmh);
  const double tacho_full = TachoFullScaleRpm(g);
  Dial(p, l.tacho_B, l.gauge_normal_B, l.gauge_radius, tacho_full, 1000, g.engine_rpm_limit,
       v.engine_rpm);
  GearDigit(p, l.gear_B, l.gauge_normal_B, 0.034, v);
  SteeringWheel(p, l, v.hand_wheel_rad);
  // The A-pillars from the windscreen's base to the roof's front edge.
  const double z_roof = cab.z_roof_front;
  for (double side : {1.0, -1.0}) {
    list.Cylinder(v.pose_WB * Vec3{cab.x_cowl, side * 0.9 * hw, cab.z_belt_cowl},
                  v.pose_WB * Vec3{cab.x_roof_front, side * 0.7 * hw, z_roof - 0.02}, 0.03,
                  kTrimDark, true, 8);
    // The door panel up to the belt line.
    const double y0 = side * 0.86 * hw, y1 = side * 0.93 * hw;
    p.Box({seat_B.x - 0.8, std::min(y0, y1), z_floor}, {x_cowl, std::max(y0, y1), cab.H(0.95)},
          kDoor);
  }
  // The roof's front edge (the header) and its lining.
  p.Box({cab.x_roof_front - 0.09, -0.75 * hw, z_roof - 0.075},
        {cab.x_roof_front + 0.01, 0.75 * hw, z_roof - 0.01}, kTrimDark);
  p.Box({cab.x_roof_rear, -0.75 * hw, z_roof - 0.045},
        {cab.x_roof_front - 0.09, 0.75 * hw, z_roof - 0.01}, kLining);
  MirrorHousings(p, MirrorsFor(g, seat_B), cab);
}

}  // namespace vdyn::viewer
