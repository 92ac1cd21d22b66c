#include "vdyn/foxglove/scene.h"

#include <algorithm>
#include <cmath>

#include "foxglove/FrameTransforms.pb.h"
#include "foxglove/SceneUpdate.pb.h"
#include "vdyn/client/palette.h"

namespace vdyn::foxglove {
namespace {

namespace fg = ::foxglove;

Vec3 operator+(const Vec3& a, const Vec3& b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}
Vec3 operator-(const Vec3& a, const Vec3& b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
Vec3 operator*(const Vec3& a, double s) {
  return {a.x * s, a.y * s, a.z * s};
}
double Dot(const Vec3& a, const Vec3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
double Norm(const Vec3& v) {
  return std::sqrt(Dot(v, v));
}
Vec3 Normalized(const Vec3& v, const Vec3& fallback) {
  const double n = Norm(v);
  return n > 1e-12 ? v * (1.0 / n) : fallback;
}
Vec3 V(const pb::Vec3& v) {
  return {v.x(), v.y(), v.z()};
}

// The body's axes in the world frame (columns of R_WB) from a quaternion, normalised first.
struct Axes {
  Vec3 x, y, z;
  Vec3 operator*(const Vec3& v) const { return x * v.x + y * v.y + z * v.z; }
  Vec3 Transposed(const Vec3& v) const { return {Dot(x, v), Dot(y, v), Dot(z, v)}; }
};
Axes AxesOf(const pb::Quat& q) {
  double w = q.w(), x = q.x(), y = q.y(), z = q.z();
  const double n = std::sqrt(w * w + x * x + y * y + z * z);
  w /= n, x /= n, y /= n, z /= n;
  return {{1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)},
          {2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)},
          {2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)}};
}

void SetVec(fg::Vector3* out, const Vec3& v) {
  out->set_x(v.x), out->set_y(v.y), out->set_z(v.z);
}
void SetQuat(fg::Quaternion* out, double w, double x, double y, double z) {
  out->set_x(x), out->set_y(y), out->set_z(z), out->set_w(w);
}
void SetColour(fg::Color* out, Rgb8 c, double a = 1.0) {
  out->set_r(c.r / 255.0), out->set_g(c.g / 255.0), out->set_b(c.b / 255.0), out->set_a(a);
}
void SetStamp(google::protobuf::Timestamp* t, std::int64_t ns) {
  const std::int64_t s = ns >= 0 ? ns / 1'000'000'000 : (ns - 999'999'999) / 1'000'000'000;
  t->set_seconds(s);
  t->set_nanos(static_cast<std::int32_t>(ns - s * 1'000'000'000));
}
// The rotation that turns +X onto the unit vector d (an arrow's orientation).
void SetRotationFromX(fg::Quaternion* out, const Vec3& d) {
  if (d.x < -1 + 1e-9) return SetQuat(out, 0, 0, 0, 1);  // half a turn about Z
  // q = (1 + d.x, X x d) normalised: half the angle between X and d.
  const double w = 1 + d.x, y = -d.z, z = d.y;
  const double n = std::sqrt(w * w + y * y + z * z);
  SetQuat(out, w / n, 0, y / n, z / n);
}

// A mid-size car (the server's defaults), for a vehicle whose geometry has not arrived yet.
Geometry DefaultGeometry() {
  Geometry g;
  const double b = 1.2, c = 1.5, bl = 0.78, bp = 0.78, z = -0.02;
  g.mount_B = {Vec3{b, bl, z}, Vec3{b, -bp, z}, Vec3{-c, bl, z}, Vec3{-c, -bp, z}};
  g.radius.fill(0.32);
  g.free_length.fill(0.35);
  return g;
}

const pb::WheelParams& WheelOf(const pb::VehicleParams& p, int w) {
  switch (w) {
    case 0:
      return p.lf();
    case 1:
      return p.rf();
    case 2:
      return p.lr();
    default:
      return p.rr();
  }
}

bool UsableGeometry(const pb::VehicleGeometry& d) {
  if (d.mount_points_b_size() != kWheels || d.wheel_radius_size() != kWheels ||
      d.free_length_size() != kWheels) {
    return false;
  }
  for (int w = 0; w < kWheels; ++w) {
    if (!(d.wheel_radius(w) > 0 && d.wheel_radius(w) < 10) ||
        !(d.free_length(w) >= 0 && d.free_length(w) < 10) ||
        !(Norm(V(d.mount_points_b(w))) < 100)) {
      return false;
    }
  }
  return true;
}

// Heights of the body in its frame, as the viewer's built-in body (a saloon on 0.32 m wheels,
// scaled with the wheel radius): the ground under the wheels at 70 % of the free spring length.
struct BodyHeights {
  double ground = -0.59, scale = 1.0;
  double At(double h) const { return ground + h * scale; }
};
BodyHeights HeightsOf(const Geometry& g) {
  double ground = 0, r = 0;
  for (int w = 0; w < kWheels; ++w) {
    const auto i = static_cast<std::size_t>(w);
    ground += g.mount_B[i].z - 0.7 * g.free_length[i] - g.radius[i];
    r += g.radius[i];
  }
  return {ground / kWheels, std::clamp(r / kWheels / 0.32, 0.7, 1.6)};
}

fg::CubePrimitive* AddBox(fg::SceneEntity* e, double x0, double x1, double half_width, double z0,
                          double z1, Rgb8 colour, double alpha) {
  fg::CubePrimitive* c = e->add_cubes();
  SetVec(c->mutable_pose()->mutable_position(), {0.5 * (x0 + x1), 0, 0.5 * (z0 + z1)});
  SetQuat(c->mutable_pose()->mutable_orientation(), 1, 0, 0, 0);
  SetVec(c->mutable_size(), {x1 - x0, 2 * half_width, z1 - z0});
  SetColour(c->mutable_color(), colour, alpha);
  return c;
}

fg::SceneEntity* NewEntity(fg::SceneUpdate& out, const std::string& id, const std::string& frame,
                           bool frame_locked, std::int64_t stamp_ns) {
  fg::SceneEntity* e = out.add_entities();
  SetStamp(e->mutable_timestamp(), stamp_ns);
  e->set_id(id);
  e->set_frame_id(frame);
  e->set_frame_locked(frame_locked);
  return e;
}

Rgb8 SurfaceColour(pb::SurfaceKind kind) {
  switch (kind) {
    case pb::SURFACE_ROAD:
      return {70, 72, 78};
    case pb::SURFACE_OBSTACLE:
      return {200, 170, 60};
    case pb::SURFACE_ROUGH:
      return {130, 110, 85};
    case pb::SURFACE_RAMP:
      return {170, 150, 120};
    case pb::SURFACE_BARRIER:
      return {170, 200, 230};
    case pb::SURFACE_PROP:
      return {190, 190, 190};
    default:
      return {96, 138, 76};
  }
}

}  // namespace

Rgb8 ForceColour(ForceKind kind) {
  const auto& c = client::ForcePaint(kind);  // the viewer's too (client/palette.h)
  return {c[0], c[1], c[2]};
}

Rgb8 VehicleColour(std::uint32_t vehicle_id) {
  const auto& c = client::VehiclePaint(vehicle_id);  // the viewer's too (client/palette.h)
  return {c[0], c[1], c[2]};
}

std::string BodyFrame(std::uint32_t vehicle_id) {
  return "vehicle/" + std::to_string(vehicle_id) + "/body";
}

std::string WheelFrame(std::uint32_t vehicle_id, int wheel) {
  return "vehicle/" + std::to_string(vehicle_id) + "/wheel/" + std::string(WheelName(wheel));
}

Geometry GeometryFor(std::uint32_t vehicle_id, const pb::WorldDescription* world,
                     const pb::VehicleParams* params) {
  Geometry g = DefaultGeometry();
  if (world != nullptr) {
    for (const pb::VehicleGeometry& d : world->vehicles()) {
      if (d.vehicle_id() != vehicle_id || !UsableGeometry(d)) continue;
      for (int w = 0; w < kWheels; ++w) {
        const auto i = static_cast<std::size_t>(w);
        g.mount_B[i] = V(d.mount_points_b(w));
        g.radius[i] = d.wheel_radius(w);
        g.free_length[i] = d.free_length(w);
      }
      if (d.body_front() > 0 && d.body_front() < 100) g.front = d.body_front();
      if (d.body_rear() > 0 && d.body_rear() < 100) g.rear = d.body_rear();
      if (d.body_half_width() > 0 && d.body_half_width() < 100) g.half_width = d.body_half_width();
      return g;
    }
  }
  if (params != nullptr) {
    // The physics' layout: A = (b | -c, b_l | -b_p, -z_offset).
    const double b = params->has_b() ? params->b() : 1.2, c = params->has_c() ? params->c() : 1.5;
    const double bl = params->has_b_l() ? params->b_l() : 0.78;
    const double bp = params->has_b_p() ? params->b_p() : 0.78;
    const double xs[kWheels] = {b, b, -c, -c}, ys[kWheels] = {bl, -bp, bl, -bp};
    for (int w = 0; w < kWheels; ++w) {
      const pb::WheelParams& wp = WheelOf(*params, w);
      const auto i = static_cast<std::size_t>(w);
      g.mount_B[i] = {xs[w], ys[w], -(wp.has_z_offset() ? wp.z_offset() : 0.02)};
      if (wp.has_radius() && wp.radius() > 0 && wp.radius() < 10) g.radius[i] = wp.radius();
      if (wp.has_free_length() && wp.free_length() >= 0 && wp.free_length() < 10) {
        g.free_length[i] = wp.free_length();
      }
    }
    if (params->has_body_front() && params->body_front() > 0) g.front = params->body_front();
    if (params->has_body_rear() && params->body_rear() > 0) g.rear = params->body_rear();
    if (params->has_body_half_width() && params->body_half_width() > 0) {
      g.half_width = params->body_half_width();
    }
  }
  return g;
}

std::string CheckState(const pb::VehicleState& s) {
  auto who = [&] { return "state of vehicle " + std::to_string(s.vehicle_id()); };
  if (s.wheels_size() != kWheels) {
    return who() + ": " + std::to_string(s.wheels_size()) + " wheels, expected 4";
  }
  const pb::Quat& q = s.q_wb();
  const double qn = std::sqrt(q.w() * q.w() + q.x() * q.x() + q.y() * q.y() + q.z() * q.z());
  if (!(qn > 0.5 && qn < 2.0)) return who() + ": orientation quaternion is not a rotation";
  constexpr double kFar = 1e7;  // m: the table of limits' pose range
  auto far = [](const pb::Vec3& v) {
    return !(std::abs(v.x()) < kFar && std::abs(v.y()) < kFar && std::abs(v.z()) < kFar);
  };
  if (far(s.p_wt_w())) return who() + ": position beyond 1e7 m";
  for (int w = 0; w < kWheels; ++w) {
    if (far(s.wheels(w).p_a_w()) || far(s.wheels(w).p_b_w())) {
      return who() + ": wheel " + std::string(WheelName(w)) + " beyond 1e7 m";
    }
  }
  return {};
}

std::array<Arrow, kArrowsPerVehicle> ForceArrows(const pb::VehicleState& s, const Geometry& g,
                                                 const SceneOptions& o) {
  std::array<Arrow, kArrowsPerVehicle> arrows{};
  const Axes R = AxesOf(s.q_wb());
  const Vec3 T = V(s.p_wt_w());
  const Vec3 v_T = V(s.v_wt_w());
  const Vec3 w_W = R * V(s.w_wb_b());
  std::size_t k = 0;
  for (int w = 0; w < kWheels; ++w) {
    const pb::WheelState& ws = s.wheels(w);
    const Vec3 B = V(ws.p_b_w());
    // The tire's frame on the ground, as the model computes it: the steered heading projected on
    // the ground plane (t_long) and n x t_long.
    const Vec3 forward = R.x * std::cos(ws.gamma()) + R.y * std::sin(ws.gamma());
    const Vec3 n = ws.contact() ? Normalized(V(ws.n_w()), {0, 0, 1}) : Vec3{0, 0, 1};
    const Vec3 t_long = Normalized(forward - n * Dot(forward, n), R.x);
    const Vec3 t_lat = Cross(n, t_long);
    // Fb opposes the wheel's rolling: the velocity of B along the heading.
    const double roll = Dot(v_T + Cross(w_W, B - T), t_long);
    arrows[k++] = {ForceKind::kSpring, w, B, n * ws.fp()};
    if (s.model() == pb::VEHICLE_MODEL_FULL) {
      arrows[k++] = {ForceKind::kDrive, w, B, t_long * std::max(ws.fx(), 0.0)};
      arrows[k++] = {ForceKind::kBrake, w, B, t_long * std::min(ws.fx(), 0.0)};
    } else {
      arrows[k++] = {ForceKind::kDrive, w, B, t_long * ws.fh()};
      arrows[k++] = {ForceKind::kBrake, w, B, t_long * (roll >= 0 ? -ws.fb() : ws.fb())};
    }
    arrows[k++] = {ForceKind::kSide, w, B, t_lat * ws.fy()};
  }
  // Drag acts against X_B: drawn ending at the nose.
  const Vec3 drag = R.x * (-s.da());
  const Vec3 nose = T + R * Vec3{g.front, 0, 0};
  arrows[k++] = {ForceKind::kDrag, -1, nose - drag * (o.arrow_m_per_kn / 1000.0), drag};
  // The wall force from above the roof (the state does not say where the wall touched).
  const Vec3 roof = T + R * Vec3{0, 0, HeightsOf(g).At(1.46) + 0.3};
  arrows[k++] = {ForceKind::kWall, -1, roof, V(s.f_wall_w())};
  return arrows;
}

void BuildTransforms(const pb::VehicleState& s, const Geometry& g, std::int64_t stamp_ns,
                     fg::FrameTransforms& out) {
  out.Clear();
  const std::uint32_t id = s.vehicle_id();
  fg::FrameTransform* body = out.add_transforms();
  SetStamp(body->mutable_timestamp(), stamp_ns);
  body->set_parent_frame_id(kWorldFrame);
  body->set_child_frame_id(BodyFrame(id));
  SetVec(body->mutable_translation(), V(s.p_wt_w()));
  const pb::Quat& q = s.q_wb();
  SetQuat(body->mutable_rotation(), q.w(), q.x(), q.y(), q.z());
  const Axes R = AxesOf(q);
  const Vec3 T = V(s.p_wt_w());
  for (int w = 0; w < kWheels; ++w) {
    const pb::WheelState& ws = s.wheels(w);
    // The wheel's centre: one radius from B towards A (as the viewer draws it), in the body frame.
    const Vec3 A = V(ws.p_a_w()), B = V(ws.p_b_w());
    const Vec3 centre_W = B + Normalized(A - B, R.z) * g.radius[static_cast<std::size_t>(w)];
    fg::FrameTransform* t = out.add_transforms();
    SetStamp(t->mutable_timestamp(), stamp_ns);
    t->set_parent_frame_id(BodyFrame(id));
    t->set_child_frame_id(WheelFrame(id, w));
    SetVec(t->mutable_translation(), R.Transposed(centre_W - T));
    SetQuat(t->mutable_rotation(), std::cos(0.5 * ws.gamma()), 0, 0, std::sin(0.5 * ws.gamma()));
  }
}

void BuildVehicleScene(const pb::VehicleState& s, const Geometry& g, const SceneOptions& o,
                       std::int64_t stamp_ns, fg::SceneUpdate& out) {
  out.Clear();
  const std::uint32_t id = s.vehicle_id();
  const std::string prefix = "vehicle/" + std::to_string(id);
  // The body: a lower box between the bumpers and a cabin between the axles, in the body frame.
  fg::SceneEntity* body = NewEntity(out, prefix + "/body", BodyFrame(id), true, stamp_ns);
  const BodyHeights h = HeightsOf(g);
  const Rgb8 paint = VehicleColour(id);
  // The lower box starts at the wheels' centres, so the wheels show beneath it.
  AddBox(body, -g.rear, g.front, g.half_width, h.At(0.42), h.At(0.95), paint, 1.0);
  const double x_front_axle = 0.5 * (g.mount_B[0].x + g.mount_B[1].x);
  const double x_rear_axle = 0.5 * (g.mount_B[2].x + g.mount_B[3].x);
  AddBox(body, x_rear_axle - 0.25, x_front_axle - 0.55, 0.85 * g.half_width, h.At(0.95), h.At(1.42),
         {60, 75, 95}, 0.85);
  fg::TextPrimitive* label = body->add_texts();
  SetVec(label->mutable_pose()->mutable_position(), {0, 0, h.At(1.46) + 0.6});
  SetQuat(label->mutable_pose()->mutable_orientation(), 1, 0, 0, 0);
  label->set_billboard(true);
  label->set_font_size(0.6);
  SetColour(label->mutable_color(), {255, 255, 255});
  label->set_text(std::to_string(id));
  // The wheels: a cylinder each, its axis along the wheel frame's Y (a quarter turn about X).
  for (int w = 0; w < kWheels; ++w) {
    fg::SceneEntity* e = NewEntity(out, prefix + "/wheel/" + std::string(WheelName(w)),
                                   WheelFrame(id, w), true, stamp_ns);
    fg::CylinderPrimitive* c = e->add_cylinders();
    SetQuat(c->mutable_pose()->mutable_orientation(), std::sqrt(0.5), std::sqrt(0.5), 0, 0);
    const double r = g.radius[static_cast<std::size_t>(w)];
    SetVec(c->mutable_size(), {2 * r, 2 * r, 0.65 * r});
    c->set_bottom_scale(1);
    c->set_top_scale(1);
    SetColour(c->mutable_color(), {30, 30, 32});
  }
  // The forces, in the world frame: an arrow's length is |F| times the scale.
  fg::SceneEntity* forces = NewEntity(out, prefix + "/forces", kWorldFrame, false, stamp_ns);
  fg::KeyValuePair* order = forces->add_metadata();
  order->set_key("arrows");
  order->set_value(
      "per wheel LF, RF, LR, RR: spring Fp, drive Fh, brake Fb, side Fy; then drag Da, wall; "
      "length " +
      std::to_string(o.arrow_m_per_kn) + " m per kN");
  for (const Arrow& a : ForceArrows(s, g, o)) {
    const double f = Norm(a.force_W);
    const double length = f * o.arrow_m_per_kn / 1000.0;
    fg::ArrowPrimitive* p = forces->add_arrows();
    SetVec(p->mutable_pose()->mutable_position(), a.tail_W);
    SetRotationFromX(p->mutable_pose()->mutable_orientation(), Normalized(a.force_W, {1, 0, 0}));
    const double head = std::min(0.25, 0.35 * length);
    p->set_shaft_length(length - head);
    p->set_head_length(head);
    p->set_shaft_diameter(0.05);
    p->set_head_diameter(0.12);
    SetColour(p->mutable_color(), ForceColour(a.kind));
  }
}

void BuildWorldScene(const pb::WorldDescription& w, std::int64_t stamp_ns, fg::SceneUpdate& out) {
  out.Clear();
  fg::SceneEntity* e = NewEntity(out, "world/" + w.server_id(), kWorldFrame, false, stamp_ns);
  fg::KeyValuePair* name = e->add_metadata();
  name->set_key("world");
  name->set_value(w.name());
  for (const pb::Mesh& m : w.meshes()) {
    const int vertices = m.vertices_size() / 3;
    if (vertices == 0 || m.indices_size() < 3) continue;
    fg::TriangleListPrimitive* t = e->add_triangles();
    SetQuat(t->mutable_pose()->mutable_orientation(), 1, 0, 0, 0);
    t->mutable_points()->Reserve(vertices);
    for (int i = 0; i < vertices; ++i) {
      fg::Point3* p = t->add_points();
      p->set_x(m.vertices(3 * i)), p->set_y(m.vertices(3 * i + 1)), p->set_z(m.vertices(3 * i + 2));
    }
    const int indices = m.indices_size() - m.indices_size() % 3;
    t->mutable_indices()->Reserve(indices);
    for (int i = 0; i < indices; ++i) {
      // An index past the vertices would make the whole list unreadable: such a triangle goes.
      const int tri = i - i % 3;
      if (m.indices(tri) >= static_cast<std::uint32_t>(vertices) ||
          m.indices(tri + 1) >= static_cast<std::uint32_t>(vertices) ||
          m.indices(tri + 2) >= static_cast<std::uint32_t>(vertices)) {
        i = tri + 2;
        continue;
      }
      t->add_indices(m.indices(i));
    }
    SetColour(t->mutable_color(), SurfaceColour(m.kind()),
              m.kind() == pb::SURFACE_BARRIER ? 0.35 : 1.0);
  }
  for (const pb::Landmark& l : w.landmarks()) {
    fg::TextPrimitive* text = e->add_texts();
    SetVec(text->mutable_pose()->mutable_position(), V(l.p_w()) + Vec3{0, 0, 2});
    SetQuat(text->mutable_pose()->mutable_orientation(), 1, 0, 0, 0);
    text->set_billboard(true);
    text->set_font_size(14);
    text->set_scale_invariant(true);
    SetColour(text->mutable_color(), {255, 255, 255});
    text->set_text(l.name());
  }
}

}  // namespace vdyn::foxglove
