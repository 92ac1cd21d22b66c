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
  // The body, the wheels, and the shadow the body casts (1.5 m beside it at most): a vehicle just
  // out of sight may still darken the ground in view.
  double r = std::hypot(std::max(g.front, g.rear), g.half_width) + 1.5;
  double longest = 0;
  for (const ForceArrow& a : v.arrows) longest = std::max(longest, Norm(a.force_W));
  return r + longest * style.metres_per_newton;
}

namespace {

// The plane z = a + b x + c y through the contact points (least squares), or false when fewer
// than three wheels touch the ground.
bool ContactPlane(const VehicleView& v, double& a, double& b, double& c) {
  double n = 0, sx = 0, sy = 0, sz = 0, sxx = 0, sxy = 0, syy = 0, sxz = 0, syz = 0;
  for (const WheelView& w : v.wheels) {
    if (!w.contact) continue;
    const Vec3& p = w.contact_W;
    n += 1;
    sx += p.x;
    sy += p.y;
    sz += p.z;
    sxx += p.x * p.x;
    sxy += p.x * p.y;
    syy += p.y * p.y;
    sxz += p.x * p.z;
    syz += p.y * p.z;
  }
  if (n < 3) return false;
  // Centred normal equations for b, c; a from the means.
  const double mx = sx / n, my = sy / n, mz = sz / n;
  const double cxx = sxx / n - mx * mx, cxy = sxy / n - mx * my, cyy = syy / n - my * my;
  const double cxz = sxz / n - mx * mz, cyz = syz / n - my * mz;
  const double det = cxx * cyy - cxy * cxy;
  if (std::abs(det) < 1e-12) {
    b = c = 0;
  } else {
    b = (cxz * cyy - cyz * cxy) / det;
    c = (cyz * cxx - cxz * cxy) / det;
  }
  a = mz - b * mx - c * my;
  return true;
}

}  // namespace

void AppendVehicleBody(const VehicleView& v, VehicleParts parts, bool coarse, FrameLists& lists) {
  if (parts.body) {
    BodyInstance b;
    b.vehicle_id = v.id;
    b.pose_WB = v.pose_WB;
    b.geometry = v.geometry;
    b.paint = VehicleColour(v.id);
    b.coarse = coarse;
    b.brake_lights = v.braking;
    b.reverse_lights = v.reversing;
    lists.bodies.push_back(b);
    double a = 0, bx = 0, cy = 0;
    if (ContactPlane(v, a, bx, cy)) {
      const VehicleGeometry& g = v.geometry;
      const double x0 = -g.rear - 0.25, x1 = g.front + 0.25, y = g.half_width + 0.2;
      ContactShadow s;
      const Vec3 corners_B[4] = {{x0, -y, 0}, {x1, -y, 0}, {x1, y, 0}, {x0, y, 0}};
      for (int i = 0; i < 4; ++i) {
        const Vec3 p = v.pose_WB * corners_B[i];
        s.corners_W[static_cast<std::size_t>(i)] = {p.x, p.y, a + bx * p.x + cy * p.y};
      }
      lists.contact_shadows.push_back(s);
    }
  }
  if (parts.wheels) {
    for (const WheelView& w : v.wheels) {
      WheelInstance wi;
      wi.centre_W = w.centre_W;
      // Turned about the axle (left) by the spin: forward tips down, up tips forward.
      const double c = std::cos(w.spin), s = std::sin(w.spin);
      const Vec3 up = Normalized(Cross(w.forward_W, w.left_W), w.up_W);
      wi.R_WW.c[0] = w.forward_W * c - up * s;
      wi.R_WW.c[1] = w.left_W;
      wi.R_WW.c[2] = w.forward_W * s + up * c;
      wi.radius = w.radius;
      wi.coarse = coarse;
      lists.wheels.push_back(wi);
    }
  }
}

}  // namespace vdyn::viewer
