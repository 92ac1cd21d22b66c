#include "vdyn/bridge/convert.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "vdyn/base/hash.h"

namespace vdyn {
namespace {

void SetVec(pb::Vec3* v, const Eigen::Vector3d& e) {
  v->set_x(e.x());
  v->set_y(e.y());
  v->set_z(e.z());
}

SteerMode FromProto(pb::SteerMode m) {
  switch (m) {
    case pb::STEER_HAND_WHEEL: return SteerMode::kHandWheel;
    case pb::STEER_HANDS_OFF: return SteerMode::kHandsOff;
    default: return SteerMode::kRoadWheel;  // STEER_ROAD_WHEEL, and any unknown value
  }
}

pb::SteerMode ToProto(SteerMode m) {
  switch (m) {
    case SteerMode::kHandWheel: return pb::STEER_HAND_WHEEL;
    case SteerMode::kHandsOff: return pb::STEER_HANDS_OFF;
    case SteerMode::kRoadWheel: break;
  }
  return pb::STEER_ROAD_WHEEL;
}

// Gear numbers beyond int's range cannot reach the physics (the server refuses them first);
// clamp anyway so a conversion never overflows.
int GearFrom(std::int32_t g) { return std::clamp<std::int32_t>(g, -1000, 1000); }

}  // namespace

DriverInput FromProto(const pb::DriverInput& in) {
  DriverInput d;
  d.steer = in.steer();
  d.throttle = in.throttle();
  d.brake = in.brake();
  d.cruise_on = in.cruise_on();
  d.cruise_speed = in.cruise_set_kmh() / 3.6;
  d.steer_mode = FromProto(in.steer_mode());
  d.clutch = in.clutch();
  d.handbrake = in.handbrake();
  d.gear = GearFrom(in.gear());
  return d;
}

void ToProto(const DriverInput& in, pb::DriverInput& out) {
  out.set_steer(in.steer);
  out.set_throttle(in.throttle);
  out.set_brake(in.brake);
  out.set_cruise_on(in.cruise_on);
  out.set_cruise_set_kmh(in.cruise_speed * 3.6);
  out.set_steer_mode(ToProto(in.steer_mode));
  out.set_clutch(in.clutch);
  out.set_handbrake(in.handbrake);
  out.set_gear(in.gear);
}

DriverInput FromManeuver(const ManeuverInput& in) {
  DriverInput d;
  d.steer = in.steer;
  d.throttle = in.throttle;
  d.brake = in.brake;
  d.cruise_on = in.cruise_on;
  d.cruise_speed = in.cruise_speed;
  return d;
}

void ToInputSample(const DriverInput& in, std::int64_t step, pb::InputSample& out) {
  out.set_step(static_cast<std::uint64_t>(step));
  out.set_steer(in.steer);
  out.set_throttle(in.throttle);
  out.set_brake(in.brake);
  out.set_cruise_on(in.cruise_on);
  out.set_cruise_speed_mps(in.cruise_speed);
  out.set_steer_mode(ToProto(in.steer_mode));
  out.set_clutch(in.clutch);
  out.set_handbrake(in.handbrake);
  out.set_gear(in.gear);
}

DriverInput FromInputSample(const pb::InputSample& s) {
  DriverInput d;
  d.steer = s.steer();
  d.throttle = s.throttle();
  d.brake = s.brake();
  d.cruise_on = s.cruise_on();
  d.cruise_speed = s.cruise_speed_mps();
  d.steer_mode = FromProto(s.steer_mode());
  d.clutch = s.clutch();
  d.handbrake = s.handbrake();
  d.gear = GearFrom(s.gear());
  return d;
}

pb::ExactState ToExactState(const State& s) {
  pb::ExactState m;
  const int n = IntegratedSize(s.model);
  for (int i = 0; i < n; ++i) m.add_x(s.x[i]);
  m.set_cruise_integral(s.cruise_integral);
  m.set_step(static_cast<std::uint64_t>(s.step));
  if (s.model == VehicleModel::kFull) {
    m.set_gear(s.discrete.gear);
    m.set_shift_time(s.discrete.shift_time);
    for (double a : s.discrete.abs) m.add_abs(a);
    m.set_tc(s.discrete.tc);
  }
  return m;
}

State FromExactState(const pb::ExactState& m) {
  State s;
  if (m.x_size() == kStateSize) {
    s.model = VehicleModel::kFull;
  } else if (m.x_size() != kPaperStateSize) {
    throw std::invalid_argument("a state has " + std::to_string(kPaperStateSize) +
                                " numbers (the paper's model) or " + std::to_string(kStateSize) +
                                " (the full model), got " + std::to_string(m.x_size()));
  }
  for (int i = 0; i < m.x_size(); ++i) s.x[i] = m.x(i);
  s.cruise_integral = m.cruise_integral();
  s.step = static_cast<std::int64_t>(m.step());
  if (!s.x.allFinite() || !std::isfinite(s.cruise_integral)) {
    throw std::invalid_argument("the state holds a non-finite number");
  }
  if (s.model == VehicleModel::kFull) {
    if (m.abs_size() != kNumWheels) {
      throw std::invalid_argument("a full-model state has 4 ABS factors, got " +
                                  std::to_string(m.abs_size()));
    }
    if (m.gear() < -1 || m.gear() > kMaxGears) {
      throw std::invalid_argument("a state's gear must be in [-1, " + std::to_string(kMaxGears) +
                                  "], got " + std::to_string(m.gear()));
    }
    s.discrete.gear = m.gear();
    s.discrete.shift_time = m.shift_time();
    for (int w = 0; w < kNumWheels; ++w) s.discrete.abs[w] = m.abs(w);
    s.discrete.tc = m.tc();
    bool finite = std::isfinite(s.discrete.shift_time) && std::isfinite(s.discrete.tc);
    for (double a : s.discrete.abs) finite = finite && std::isfinite(a);
    if (!finite) throw std::invalid_argument("the state holds a non-finite number");
  }
  return s;
}

void FillVehicleState(std::uint32_t vehicle_id, const std::string& server_id,
                      std::int64_t step_ns, std::int64_t sim_time_ns, const StepRecord& r,
                      const pb::DriverInput& input, bool watchdog_safe_state,
                      double steering_torque, pb::VehicleState& out) {
  const Eigen::Matrix3d R = Orientation(r.state.x).toRotationMatrix();
  const bool full = r.state.model == VehicleModel::kFull;
  out.set_vehicle_id(vehicle_id);
  out.set_server_id(server_id);
  out.set_step(static_cast<std::uint64_t>(r.step));
  out.set_sim_time_ns(sim_time_ns);
  out.set_step_ns(step_ns);
  SetVec(out.mutable_p_wt_w(), Position(r.state.x));
  auto* q = out.mutable_q_wb();
  q->set_w(r.state.x[sx::kQ]);
  q->set_x(r.state.x[sx::kQ + 1]);
  q->set_y(r.state.x[sx::kQ + 2]);
  q->set_z(r.state.x[sx::kQ + 3]);
  SetVec(out.mutable_rpy(), RollPitchYaw(Orientation(r.state.x)));
  SetVec(out.mutable_v_wt_b(), R.transpose() * Velocity(r.state.x));
  SetVec(out.mutable_v_wt_w(), Velocity(r.state.x));
  SetVec(out.mutable_w_wb_b(), r.derived.w_eff_B);
  SetVec(out.mutable_a_wt_b(), R.transpose() * r.derived.a_WT_W);
  SetVec(out.mutable_a_wt_w(), r.derived.a_WT_W);
  SetVec(out.mutable_dw_wb_b(), r.derived.dw_B);
  out.set_da(r.derived.Da);
  SetVec(out.mutable_f_wall_w(), r.derived.F_wall_W);
  out.set_wall_pen(r.derived.wall_penetration_max);
  if (out.wheels_size() != kNumWheels) {
    out.clear_wheels();
    for (int w = 0; w < kNumWheels; ++w) out.add_wheels();
  }
  for (int w = 0; w < kNumWheels; ++w) {
    const WheelOutputs& o = r.derived.wheel[w];
    pb::WheelState* ws = out.mutable_wheels(w);
    ws->set_contact(o.contact);
    ws->set_fp(o.Fp);
    ws->set_fh(o.Fh);
    ws->set_fb(o.Fb);
    ws->set_fy(o.Fy);
    ws->set_frr(o.Frr);
    ws->set_ls(o.lS);
    ws->set_lt(o.lT);
    ws->set_dls(o.lS_rate);
    ws->set_gamma(o.gamma);
    ws->set_slip(o.slip_angle);
    SetVec(ws->mutable_p_a_w(), o.p_A_W);
    SetVec(ws->mutable_p_b_w(), o.p_B_W);
    SetVec(ws->mutable_n_w(), o.n_W);
    SetVec(ws->mutable_f_w(), o.F_W);
    ws->set_omega(o.omega);
    ws->set_slip_ratio(o.slip_ratio);
    ws->set_fx(o.Fx);
    ws->set_mz(o.Mz);
    ws->set_drive_torque(o.drive_torque);
    ws->set_brake_torque(o.brake_torque);
    ws->set_slip_ratio_t(o.slip_ratio_t);
    ws->set_slip_angle_t(o.slip_angle_t);
    ws->set_v_long(o.v_long);
    ws->set_abs_factor(r.control.abs_factor[w]);
    ws->set_kerb(o.kerb);
    ws->set_kappa_law(o.kappa_law);
    ws->set_alpha_law(o.alpha_law);
    ws->set_camber(o.camber);
    ws->set_pressure(o.pressure);
    ws->set_mx(o.Mx);
    ws->set_my(o.My);
  }
  *out.mutable_input() = input;
  pb::AppliedControl* c = out.mutable_control();
  c->set_gamma(r.control.gamma);
  c->set_throttle(r.control.throttle);
  c->set_brake(r.control.brake);
  c->set_cruise_u(r.control.cruise_u);
  c->set_cruise_active(r.control.cruise_active);
  c->set_watchdog_safe_state(watchdog_safe_state);
  out.set_state_hash(r.hash_after);
  out.set_steering_torque(steering_torque);
  out.set_speed_kmh(3.6 * Velocity(r.state.x).norm());
  out.set_model(full ? pb::VEHICLE_MODEL_FULL : pb::VEHICLE_MODEL_PAPER);
  // The full model's steering system and drivetrain (zero for the paper's model).
  const Derived::Steering& st = r.derived.steering;
  pb::SteeringState* ps = out.mutable_steering();
  ps->set_hand_wheel_angle(st.angle);
  ps->set_hand_wheel_rate(st.rate);
  ps->set_torque_aligning(st.aligning);
  ps->set_torque_trail(st.trail);
  ps->set_torque_friction(st.friction);
  ps->set_torque_damping(st.damping);
  ps->set_torque_end_stop(st.end_stop);
  ps->set_driver_torque(st.driver);
  ps->set_hands_on(full && r.control.hands_on);
  const Derived::Drivetrain& dt = r.derived.drivetrain;
  pb::DrivetrainState* pd = out.mutable_drivetrain();
  pd->set_engine_rpm(dt.engine_speed * 60.0 / (2.0 * 3.14159265358979323846));
  pd->set_engine_torque(dt.engine_torque);
  pd->set_gear(full ? r.control.gear : 0);
  pd->set_shifting(full && r.control.shifting);
  pd->set_automatic(full && r.control.automatic);
  pd->set_clutch_torque(dt.clutch_torque);
  pd->set_clutch_slip_rpm(dt.clutch_slip * 60.0 / (2.0 * 3.14159265358979323846));
  pd->set_throttle(dt.throttle);
  pd->set_tc_factor(r.control.tc_factor);
}

std::uint64_t TerrainHash(const Terrain& terrain) {
  base::WordHash h;
  for (const TriangleMesh& m : terrain.meshes()) {
    for (const Eigen::Vector3d& v : m.vertices_W) {
      h.Double(v.x());
      h.Double(v.y());
      h.Double(v.z());
    }
    for (const auto& t : m.triangles) {
      for (std::uint32_t i : t) h.Int(i);
    }
  }
  return h.Final();
}

std::uint64_t TerrainHash(const pb::WorldDescription& world) {
  base::WordHash h;
  for (const pb::Mesh& m : world.meshes()) {
    for (double v : m.vertices()) h.Double(v);
    for (std::uint32_t i : m.indices()) h.Int(i);
  }
  return h.Final();
}

std::unique_ptr<World> WorldFromDescription(const pb::WorldDescription& d) {
  auto world = std::make_unique<World>();
  world->name = d.name();
  world->north_yaw = d.north_yaw();
  world->spawn = {d.spawn().x(), d.spawn().y(), d.spawn().yaw()};
  for (const pb::Mesh& pm : d.meshes()) {
    if (pm.vertices_size() % 3 != 0 || pm.indices_size() % 3 != 0) {
      throw WorldError("world '" + d.name() + "', mesh '" + pm.name() +
                       "': vertex and index counts must be multiples of 3");
    }
    TriangleMesh m;
    m.name = pm.name();
    const int kind = static_cast<int>(pm.kind());
    m.kind = kind >= 0 && kind <= static_cast<int>(SurfaceKind::kProp)
                 ? static_cast<SurfaceKind>(kind)
                 : SurfaceKind::kGround;
    m.vertices_W.reserve(static_cast<std::size_t>(pm.vertices_size() / 3));
    for (int i = 0; i + 2 < pm.vertices_size(); i += 3) {
      m.vertices_W.emplace_back(pm.vertices(i), pm.vertices(i + 1), pm.vertices(i + 2));
    }
    for (int i = 0; i + 2 < pm.indices_size(); i += 3) {
      m.triangles.push_back({pm.indices(i), pm.indices(i + 1), pm.indices(i + 2)});
    }
    try {
      world->terrain.AddMesh(std::move(m));
    } catch (const std::invalid_argument& e) {
      throw WorldError("world '" + d.name() + "': " + e.what());
    }
  }
  if (world->terrain.triangle_count() == 0) {
    throw WorldError("world '" + d.name() + "' holds no usable triangle");
  }
  world->terrain.Commit();
  for (const pb::Landmark& l : d.landmarks()) {
    world->landmarks.push_back({l.name(), Eigen::Vector3d(l.p_w().x(), l.p_w().y(), l.p_w().z())});
  }
  return world;
}

pb::WorldDescription DescribeWorld(const World& world, const std::string& server_id,
                                   std::int64_t step_ns) {
  pb::WorldDescription d;
  d.set_server_id(server_id);
  d.set_name(world.name);
  d.set_north_yaw(world.north_yaw);
  for (const TriangleMesh& m : world.terrain.meshes()) {
    pb::Mesh* pm = d.add_meshes();
    pm->set_name(m.name);
    pm->set_kind(static_cast<pb::SurfaceKind>(static_cast<int>(m.kind)));
    pm->mutable_vertices()->Reserve(static_cast<int>(3 * m.vertices_W.size()));
    for (const Eigen::Vector3d& v : m.vertices_W) {
      pm->add_vertices(v.x());
      pm->add_vertices(v.y());
      pm->add_vertices(v.z());
    }
    pm->mutable_indices()->Reserve(static_cast<int>(3 * m.triangles.size()));
    for (const auto& t : m.triangles) {
      for (std::uint32_t i : t) pm->add_indices(i);
    }
  }
  for (const Landmark& l : world.landmarks) {
    pb::Landmark* pl = d.add_landmarks();
    pl->set_name(l.name);
    SetVec(pl->mutable_p_w(), l.p_W);
  }
  d.mutable_spawn()->set_x(world.spawn.x);
  d.mutable_spawn()->set_y(world.spawn.y);
  d.mutable_spawn()->set_yaw(world.spawn.yaw);
  d.set_step_ns(step_ns);
  d.set_terrain_hash(TerrainHash(world.terrain));
  return d;
}

pb::VehicleGeometry DescribeVehicle(std::uint32_t vehicle_id, const Params& p) {
  pb::VehicleGeometry g;
  g.set_vehicle_id(vehicle_id);
  for (int w = 0; w < kNumWheels; ++w) {
    SetVec(g.add_mount_points_b(), p.p_TA_B[w]);
    g.add_wheel_radius(p.wheel[w].radius);
    g.add_free_length(p.wheel[w].free_length);
  }
  g.set_body_front(p.body_front);
  g.set_body_rear(p.body_rear);
  g.set_body_half_width(p.body_half_width);
  return g;
}

}  // namespace vdyn
