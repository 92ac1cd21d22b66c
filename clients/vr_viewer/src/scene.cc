#include "vdyn/viewer/scene.h"

#include <algorithm>
#include <cmath>

#include "vdyn/client/palette.h"
#include "vdyn/viewer/car_model.h"

namespace vdyn::viewer {
namespace {

Vec3 V(const pb::Vec3& v) {
  return {v.x(), v.y(), v.z()};
}

// A mid-size car (the server's defaults), for a vehicle whose geometry has not arrived yet.
VehicleGeometry DefaultGeometry() {
  VehicleGeometry g;
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

}  // namespace

Rgb8 ForceColour(ForceKind kind) {
  const auto& c = client::ForcePaint(kind);  // the Foxglove scenes' too (client/palette.h)
  return {c[0], c[1], c[2]};
}

Rgb8 VehicleColour(std::uint32_t vehicle_id) {
  const auto& c = client::VehiclePaint(vehicle_id);  // the clients' shared palette
  return {c[0], c[1], c[2]};
}

std::string CheckGeometry(const pb::VehicleGeometry& g) {
  if (g.mount_points_b_size() != kWheels || g.wheel_radius_size() != kWheels ||
      g.free_length_size() != kWheels) {
    return "vehicle " + std::to_string(g.vehicle_id()) +
           ": geometry needs 4 mount points, radii and free lengths, got " +
           std::to_string(g.mount_points_b_size()) + ", " + std::to_string(g.wheel_radius_size()) +
           ", " + std::to_string(g.free_length_size());
  }
  for (int w = 0; w < kWheels; ++w) {
    const double r = g.wheel_radius(w), l = g.free_length(w);
    if (!(r > 0 && r < 10) || !(l >= 0 && l < 10)) {
      return "vehicle " + std::to_string(g.vehicle_id()) + ": wheel " + std::string(WheelName(w)) +
             " radius or free length out of (0, 10) m";
    }
    const Vec3 a = V(g.mount_points_b(w));
    if (!(Norm(a) < 100)) {
      return "vehicle " + std::to_string(g.vehicle_id()) + ": mount point " +
             std::string(WheelName(w)) + " more than 100 m from T";
    }
  }
  for (double d : {g.body_front(), g.body_rear(), g.body_half_width()}) {
    if (!(d >= 0 && d < 100)) {
      return "vehicle " + std::to_string(g.vehicle_id()) + ": body box out of [0, 100) m";
    }
  }
  return {};
}

VehicleGeometry GeometryFor(std::uint32_t vehicle_id, const pb::WorldDescription* world,
                            const pb::VehicleParams* params) {
  VehicleGeometry g = DefaultGeometry();
  if (params != nullptr) {
    if (params->has_steering_ratio() && params->steering_ratio() > 0 &&
        params->steering_ratio() < 100) {
      g.steering_ratio = params->steering_ratio();
    }
    if (params->has_engine_rpm_limit() && params->engine_rpm_limit() > 500 &&
        params->engine_rpm_limit() < 30000) {
      g.engine_rpm_limit = params->engine_rpm_limit();
    }
  }
  if (world != nullptr) {
    for (const pb::VehicleGeometry& d : world->vehicles()) {
      if (d.vehicle_id() != vehicle_id || !CheckGeometry(d).empty()) continue;
      for (int w = 0; w < kWheels; ++w) {
        g.mount_B[static_cast<std::size_t>(w)] = V(d.mount_points_b(w));
        g.radius[static_cast<std::size_t>(w)] = d.wheel_radius(w);
        g.free_length[static_cast<std::size_t>(w)] = d.free_length(w);
      }
      if (d.body_front() > 0) g.front = d.body_front();
      if (d.body_rear() > 0) g.rear = d.body_rear();
      if (d.body_half_width() > 0) g.half_width = d.body_half_width();
      g.source = VehicleGeometry::Source::kWorld;
      return g;
    }
  }
  if (params != nullptr) {
    // The physics' layout (server/physics params.cc): A = (b | -c, b_l | -b_p, -z_offset).
    const double b = params->has_b() ? params->b() : 1.2, c = params->has_c() ? params->c() : 1.5;
    const double bl = params->has_b_l() ? params->b_l() : 0.78;
    const double bp = params->has_b_p() ? params->b_p() : 0.78;
    const double xs[kWheels] = {b, b, -c, -c}, ys[kWheels] = {bl, -bp, bl, -bp};
    for (int w = 0; w < kWheels; ++w) {
      const pb::WheelParams& wp = WheelOf(*params, w);
      const auto i = static_cast<std::size_t>(w);
      g.mount_B[i] = {xs[w], ys[w], -(wp.has_z_offset() ? wp.z_offset() : 0.02)};
      if (wp.has_radius() && wp.radius() > 0) g.radius[i] = wp.radius();
      if (wp.has_free_length() && wp.free_length() >= 0) g.free_length[i] = wp.free_length();
    }
    if (params->has_body_front() && params->body_front() > 0) g.front = params->body_front();
    if (params->has_body_rear() && params->body_rear() > 0) g.rear = params->body_rear();
    if (params->has_body_half_width() && params->body_half_width() > 0) {
      g.half_width = params->body_half_width();
    }
    g.source = VehicleGeometry::Source::kParams;
  }
  return g;
}

std::string CheckState(const pb::VehicleState& s) {
  const std::string who = "state of vehicle " + std::to_string(s.vehicle_id());
  if (s.wheels_size() != kWheels) {
    return who + ": " + std::to_string(s.wheels_size()) + " wheels, expected 4";
  }
  const pb::Quat& q = s.q_wb();
  const double qn = std::sqrt(q.w() * q.w() + q.x() * q.x() + q.y() * q.y() + q.z() * q.z());
  if (!(qn > 0.5 && qn < 2.0)) return who + ": orientation quaternion is not a rotation";
  constexpr double kFar = 1e7;  // m: the table of limits' pose range
  auto far = [](const pb::Vec3& v) {
    return !(std::abs(v.x()) < kFar && std::abs(v.y()) < kFar && std::abs(v.z()) < kFar);
  };
  if (far(s.p_wt_w())) return who + ": position beyond 1e7 m";
  for (int w = 0; w < kWheels; ++w) {
    if (far(s.wheels(w).p_a_w()) || far(s.wheels(w).p_b_w())) {
      return who + ": wheel " + std::string(WheelName(w)) + " beyond 1e7 m";
    }
  }
  return {};
}

double WheelSpinRate(const pb::VehicleState& s, int wheel) {
  const pb::WheelState& ws = s.wheels(wheel);
  if (s.model() == pb::VEHICLE_MODEL_FULL) return ws.omega();
  // The paper model: B rolls along the wheel's heading in the ground plane without slip.
  const pb::Quat& q = s.q_wb();
  const Mat3 R = RotationFromQuat(q.w(), q.x(), q.y(), q.z());
  const Vec3 B = V(ws.p_b_w()), A = V(ws.p_a_w());
  const Vec3 v_B = V(s.v_wt_w()) + Cross(R * V(s.w_wb_b()), B - V(s.p_wt_w()));
  const Vec3 forward = R.c[0] * std::cos(ws.gamma()) + R.c[1] * std::sin(ws.gamma());
  const Vec3 n = ws.contact() ? Normalized(V(ws.n_w()), Vec3{0, 0, 1}) : R.c[2];
  const Vec3 t_long = Normalized(forward - n * Dot(forward, n), R.c[0]);
  // The radius: from A to B is the spring's length plus the radius.
  double radius = Norm(A - B) - ws.ls();
  if (!(radius > 0.05)) radius = 0.3;
  return Dot(v_B, t_long) / radius;
}

void AdvanceWheelSpin(WheelSpin& spin, const pb::VehicleState& s) {
  std::array<double, kWheels> rate{};
  for (int w = 0; w < kWheels; ++w) rate[static_cast<std::size_t>(w)] = WheelSpinRate(s, w);
  if (spin.started && s.sim_time_ns() > spin.sim_time_ns) {
    const double dt = static_cast<double>(s.sim_time_ns() - spin.sim_time_ns) * 1e-9;
    for (std::size_t w = 0; w < kWheels; ++w) {
      spin.angle[w] = WrapAngle(spin.angle[w] + 0.5 * (spin.rate[w] + rate[w]) * dt);
    }
  }
  spin.rate = rate;
  spin.sim_time_ns = s.sim_time_ns();
  spin.started = true;
}

VehicleView BuildVehicleView(const pb::VehicleState& s, const VehicleGeometry& g,
                             const WheelSpin* spin) {
  VehicleView v;
  v.id = s.vehicle_id();
  v.step = s.step();
  v.geometry = g;
  v.speed_kmh = s.speed_kmh();
  const pb::Quat& q = s.q_wb();
  v.pose_WB.R = RotationFromQuat(q.w(), q.x(), q.y(), q.z());
  v.pose_WB.t = V(s.p_wt_w());
  const Vec3 x_B = v.pose_WB.R.c[0], y_B = v.pose_WB.R.c[1], z_B = v.pose_WB.R.c[2];
  v.yaw = std::atan2(x_B.y, x_B.x);
  const Vec3 T = v.pose_WB.t;
  const Vec3 v_T = V(s.v_wt_w());
  const Vec3 w_W = v.pose_WB.R * V(s.w_wb_b());

  v.arrows.reserve(4 * kWheels + 2);
  double ground = 0;
  for (int w = 0; w < kWheels; ++w) {
    const pb::WheelState& ws = s.wheels(w);
    WheelView& wv = v.wheels[static_cast<std::size_t>(w)];
    wv.radius = g.radius[static_cast<std::size_t>(w)];
    wv.contact = ws.contact();
    if (spin != nullptr) wv.spin = spin->angle[static_cast<std::size_t>(w)];
    wv.mount_W = V(ws.p_a_w());
    wv.contact_W = V(ws.p_b_w());
    ground += wv.contact_W.z;
    wv.up_W = Normalized(wv.mount_W - wv.contact_W, z_B);
    wv.centre_W = wv.contact_W + wv.up_W * wv.radius;
    const double c = std::cos(ws.gamma()), sn = std::sin(ws.gamma());
    wv.forward_W = x_B * c + y_B * sn;
    wv.left_W = Normalized(Cross(z_B, wv.forward_W), y_B);
    wv.n_W = wv.contact ? Normalized(V(ws.n_w()), Vec3{0, 0, 1}) : Vec3{0, 0, 1};
    // The tire's frame on the ground, as the model computes it.
    Vec3 t_long = wv.forward_W - wv.n_W * Dot(wv.forward_W, wv.n_W);
    wv.t_long_W = Normalized(t_long, x_B);
    wv.t_lat_W = Cross(wv.n_W, wv.t_long_W);

    const Vec3 B = wv.contact_W;
    // Fb opposes the wheel's rolling: the velocity of B along the heading.
    const Vec3 v_B = v_T + Cross(w_W, B - T);
    const double roll = Dot(v_B, wv.t_long_W);
    v.arrows.push_back({ForceKind::kSpring, w, B, wv.n_W * ws.fp(), false});
    if (s.model() == pb::VEHICLE_MODEL_FULL) {
      // The full model's ground force along the wheel is the tire's Fx (from slip; the drive and
      // brake torques act on the wheel's spin): drawn as the drive arrow where it pushes the car
      // along the wheel's heading, as the brake arrow where it holds it back (docs/model.md 8).
      v.arrows.push_back({ForceKind::kDrive, w, B, wv.t_long_W * std::max(ws.fx(), 0.0), false});
      v.arrows.push_back({ForceKind::kBrake, w, B, wv.t_long_W * std::min(ws.fx(), 0.0), false});
    } else {
      v.arrows.push_back({ForceKind::kDrive, w, B, wv.t_long_W * ws.fh(), false});
      v.arrows.push_back(
          {ForceKind::kBrake, w, B, wv.t_long_W * (roll >= 0 ? -ws.fb() : ws.fb()), false});
    }
    v.arrows.push_back({ForceKind::kSide, w, B, wv.t_lat_W * ws.fy(), false});
  }
  v.ground_z = ground / kWheels;
  // The lamps.
  double brake_torque = 0, drive = 0;
  for (const pb::WheelState& ws : s.wheels()) {
    brake_torque = std::max(brake_torque, ws.brake_torque());
    drive += ws.fh() + ws.drive_torque();
  }
  v.braking = s.control().brake() > kBrakeLightInput || brake_torque > kBrakeLightTorqueNm;
  const double v_forward = Dot(v_T, x_B);
  v.reversing = s.drivetrain().gear() < 0 || (v_forward < -kReverseLightSpeed && drive < 0);
  // The cockpit's readings.
  v.has_gearbox = s.model() == pb::VEHICLE_MODEL_FULL;
  if (v.has_gearbox) {
    v.hand_wheel_rad = s.steering().hand_wheel_angle();
    v.engine_rpm = s.drivetrain().engine_rpm();
    v.gear = s.drivetrain().gear();
  } else {
    v.hand_wheel_rad = s.control().gamma() * g.steering_ratio;
  }
  // Drag acts against X_B (eq. 15, signed with vx): drawn pointing at the nose.
  const Vec3 nose = v.pose_WB * Vec3{g.front, 0, 0};
  v.arrows.push_back({ForceKind::kDrag, -1, nose, x_B * (-s.da()), true});
  // The wall force from above the roof (the state does not say where the wall touched).
  const Vec3 roof = v.pose_WB * Vec3{0, 0, CarShapeFor(g).z_roof + 0.3};
  v.arrows.push_back({ForceKind::kWall, -1, roof, V(s.f_wall_w()), false});
  return v;
}

}  // namespace vdyn::viewer
