#include "vdyn/viewer/draw_list.h"

#include <algorithm>
#include <cmath>

namespace vdyn::viewer {
namespace {

// Two unit vectors perpendicular to `axis` and to each other.
void Basis(const Vec3& axis, Vec3& u, Vec3& w) {
  const Vec3 a = Normalized(axis);
  const Vec3 helper = std::abs(a.z) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0};
  u = Normalized(Cross(a, helper));
  w = Cross(a, u);
}

constexpr Rgb8 kTyre{34, 34, 38};
constexpr Rgb8 kRim{175, 178, 185};
constexpr Rgb8 kSpring{120, 120, 128};

}  // namespace

void DrawList::Push(const Vec3& p, const Vec3& n, Rgb8 c, std::uint8_t alpha) {
  Vertex v{};
  v.p[0] = static_cast<float>(p.x);
  v.p[1] = static_cast<float>(p.y);
  v.p[2] = static_cast<float>(p.z);
  v.n[0] = static_cast<float>(n.x);
  v.n[1] = static_cast<float>(n.y);
  v.n[2] = static_cast<float>(n.z);
  v.rgba[0] = c.r;
  v.rgba[1] = c.g;
  v.rgba[2] = c.b;
  v.rgba[3] = alpha;
  vertices_.push_back(v);
}

void DrawList::Triangle(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& n, Rgb8 col,
                        std::uint8_t alpha) {
  Push(a, n, col, alpha);
  Push(b, n, col, alpha);
  Push(c, n, col, alpha);
}

void DrawList::Box(const Pose& pose, const Vec3& mn, const Vec3& mx, Rgb8 c, std::uint8_t alpha) {
  // Corners by bits: x (1), y (2), z (4).
  Vec3 p[8];
  for (int i = 0; i < 8; ++i) {
    p[i] = pose * Vec3{(i & 1) ? mx.x : mn.x, (i & 2) ? mx.y : mn.y, (i & 4) ? mx.z : mn.z};
  }
  struct Face {
    int a, b, c, d;
    Vec3 n_B;
  };
  static const Face kFaces[] = {
      {0, 2, 6, 4, {-1, 0, 0}}, {1, 5, 7, 3, {1, 0, 0}},  {0, 4, 5, 1, {0, -1, 0}},
      {2, 3, 7, 6, {0, 1, 0}},  {0, 1, 3, 2, {0, 0, -1}}, {4, 6, 7, 5, {0, 0, 1}},
  };
  for (const Face& f : kFaces) {
    const Vec3 n = pose.R * f.n_B;
    Triangle(p[f.a], p[f.b], p[f.c], n, c, alpha);
    Triangle(p[f.a], p[f.c], p[f.d], n, c, alpha);
  }
}

void DrawList::Cylinder(const Vec3& a, const Vec3& b, double radius, Rgb8 c, bool lit,
                        int segments) {
  Vec3 u, w;
  const Vec3 axis = Normalized(b - a);
  Basis(axis, u, w);
  const Vec3 zero{};
  for (int i = 0; i < segments; ++i) {
    const double t0 = 2 * kPi * i / segments, t1 = 2 * kPi * (i + 1) / segments;
    const Vec3 d0 = u * std::cos(t0) + w * std::sin(t0);
    const Vec3 d1 = u * std::cos(t1) + w * std::sin(t1);
    const Vec3 a0 = a + d0 * radius, a1 = a + d1 * radius, b0 = b + d0 * radius,
               b1 = b + d1 * radius;
    const Vec3 n = lit ? Normalized(d0 + d1) : zero;
    Triangle(a0, a1, b1, n, c);
    Triangle(a0, b1, b0, n, c);
    Triangle(a, a1, a0, lit ? -axis : zero, c);
    Triangle(b, b0, b1, lit ? axis : zero, c);
  }
}

void DrawList::Cone(const Vec3& base, const Vec3& tip, double radius, Rgb8 c, bool lit,
                    int segments) {
  Vec3 u, w;
  const Vec3 axis = Normalized(tip - base);
  Basis(axis, u, w);
  const Vec3 zero{};
  for (int i = 0; i < segments; ++i) {
    const double t0 = 2 * kPi * i / segments, t1 = 2 * kPi * (i + 1) / segments;
    const Vec3 d0 = u * std::cos(t0) + w * std::sin(t0);
    const Vec3 d1 = u * std::cos(t1) + w * std::sin(t1);
    const Vec3 n = lit ? Normalized(d0 + d1 + axis * 0.5) : zero;
    Triangle(base + d0 * radius, base + d1 * radius, tip, n, c);
    Triangle(base, base + d1 * radius, base + d0 * radius, lit ? -axis : zero, c);
  }
}

void DrawList::Arrow(const Vec3& from, const Vec3& to, double radius, Rgb8 c, int segments) {
  const double len = Norm(to - from);
  if (!(len > 1e-6)) return;
  const Vec3 dir = (to - from) / len;
  const double head = std::min(0.35 * len, 6.0 * radius);
  const Vec3 neck = to - dir * head;
  if (len - head > 1e-6) Cylinder(from, neck, radius, c, false, std::max(4, segments * 2 / 3));
  Cone(neck, to, 2.2 * radius, c, false, segments);
}

ArrowSpan ArrowSpanOf(const ForceArrow& a, const ArrowStyle& style) {
  const Vec3 d = a.force_W * style.metres_per_newton;
  return a.tip_at_anchor ? ArrowSpan{a.anchor_W - d, a.anchor_W}
                         : ArrowSpan{a.anchor_W, a.anchor_W + d};
}

double BoundingRadius(const VehicleView& v, const ArrowStyle& style) {
  const VehicleGeometry& g = v.geometry;
  double r = std::hypot(std::max(g.front, g.rear), g.half_width) + 1.5;  // body, wheels, cabin
  double longest = 0;
  for (const ForceArrow& a : v.arrows) longest = std::max(longest, Norm(a.force_W));
  return r + longest * style.metres_per_newton;
}

void AppendVehicleBody(const VehicleView& v, bool body, bool coarse, FrameLists& lists) {
  DrawList& opaque = lists.opaque;
  if (body) {
    const BodyBoxes boxes = BodyBoxesFor(v.geometry);
    const Rgb8 colour = VehicleColour(v.id);
    lists.translucent.Box(v.pose_WB, boxes.lower_min, boxes.lower_max, colour, 110);
    opaque.Box(v.pose_WB, boxes.cabin_min, boxes.cabin_max, colour);
  }
  for (const WheelView& w : v.wheels) {
    const double half_width = 0.35 * w.radius;
    opaque.Cylinder(w.centre_W - w.left_W * half_width, w.centre_W + w.left_W * half_width,
                    w.radius, kTyre, true, coarse ? 10 : 20);
    // The rim, a little proud of the tyre on both sides, shows the steering angle from above.
    opaque.Cylinder(w.centre_W - w.left_W * (half_width + 0.01),
                    w.centre_W + w.left_W * (half_width + 0.01), 0.6 * w.radius, kRim, true,
                    coarse ? 6 : 12);
    if (!coarse) opaque.Cylinder(w.mount_W, w.centre_W, 0.035, kSpring, true, 8);
  }
}

}  // namespace vdyn::viewer
