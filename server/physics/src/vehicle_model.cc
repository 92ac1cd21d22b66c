#include "vdyn/physics/vehicle_model.h"

#include <algorithm>
#include <cmath>

namespace vdyn {
namespace {

// Lift of the vertical trace's origin above A along Z_B: the trace still finds ground that has
// come up past A (a bottomed-out spring) instead of missing it.
double TraceLift(const WheelParams& w) { return w.radius; }

// Regularised sign: v / v_eps inside the band, +-1 outside (static friction without chatter).
double SoftSign(double v, double v_eps) { return std::clamp(v / v_eps, -1.0, 1.0); }

}  // namespace

double TireLateralForce(TireLaw law, double tan_alpha, double cornering_stiffness, double mu,
                        double Fz) {
  const double f_max = mu * Fz;
  if (f_max <= 0.0) return 0.0;
  if (law == TireLaw::kLinearSaturated) {
    return std::clamp(-cornering_stiffness * std::atan(tan_alpha), -f_max, f_max);
  }
  // Fiala brush model: with z = tan(alpha) and C = C_alpha,
  //   Fy = -C z + C^2 |z| z / (3 f_max) - C^3 z^3 / (27 f_max^2)   for |z| < 3 f_max / C,
  //   Fy = -f_max sign(alpha)                                     beyond (full sliding).
  const double z = tan_alpha;
  const double C = cornering_stiffness;
  const double z_slide = 3.0 * f_max / C;
  if (std::abs(z) >= z_slide) return z > 0.0 ? -f_max : f_max;
  return -C * z + C * C * std::abs(z) * z / (3.0 * f_max) -
         C * C * C * z * z * z / (27.0 * f_max * f_max);
}

bool FindWalls(const Params& p, const Terrain& terrain, const StateVector& x, WallPlanes& walls) {
  const Eigen::Matrix3d R_WB = Orientation(x).normalized().toRotationMatrix();
  const Eigen::Vector3d p_WO = Position(x) + R_WB * p.p_TO_B;
  // Look 1 m beyond the body: far more than one step's travel at any speed the model allows.
  constexpr double kLookAhead = 1.0;
  const double reach = std::max(p.body_front, p.body_rear) + p.body_half_width + kLookAhead;
  if (!terrain.SteepSurfaceNear(p_WO.x(), p_WO.y(), reach)) {
    for (WallPlane& wall : walls) wall.active = false;  // open ground: no trace needed
    return false;
  }
  for (int k = 0; k < Params::kNumProbes; ++k) {
    const Eigen::Vector3d dir_W = R_WB * p.probe_dir_B[k];
    const TraceHit hit = terrain.Trace(p_WO, dir_W, p.probe_length[k] + kLookAhead);
    WallPlane& wall = walls[k];
    wall.active = hit.hit && std::abs(hit.normal_W.z()) < Terrain::kSteepNormalZ;
    if (wall.active) {
      wall.p_W = p_WO + hit.distance * dir_W;
      wall.n_W = hit.normal_W;
    }
  }
  return true;
}

void SenseTerrain(const Params& p, const Terrain& terrain, const AppliedControl& u,
                  const StateVector& x, BodyKinematics& k, std::array<TraceHit, kNumWheels>& hits,
                  Derived& out) {
  k.R_WB = Orientation(x).normalized().toRotationMatrix();
  k.p_WT_W = Position(x);
  k.v_WT_W = Velocity(x);
  k.down_W = -k.R_WB.col(2);

  // A-B trace per wheel, the four wheels as one ray packet.
  std::array<Eigen::Vector3d, kNumWheels> origins, dirs;
  std::array<double, kNumWheels> ranges;
  for (int w = 0; w < kNumWheels; ++w) {
    const WheelParams& wp = p.wheel[w];
    WheelOutputs& o = out.wheel[w];
    o.p_A_W = k.p_WT_W + k.R_WB * p.p_TA_B[w];
    const double lift = TraceLift(wp);
    origins[w] = o.p_A_W - lift * k.down_W;
    dirs[w] = k.down_W;
    ranges[w] = lift + wp.free_length + wp.radius;
  }
  terrain.Trace4(origins, dirs, ranges, hits);
  out.any_contact = false;
  for (int w = 0; w < kNumWheels; ++w) {
    if (hits[w].hit) hits[w].distance -= TraceLift(p.wheel[w]);  // now AB from A (< 0: above A)
    out.wheel[w].contact = hits[w].hit;
    out.any_contact = out.any_contact || hits[w].hit;
  }

  // Body rates: the state's, or in the paper's yaw mode eq. 6 as a yaw rate while a wheel touches.
  k.w_WB_B = AngularVelocityB(x);
  k.paper_yaw = p.yaw_mode == YawMode::kPaper && out.any_contact;
  if (k.paper_yaw) {
    const double vx = k.R_WB.col(0).dot(k.v_WT_W);
    k.w_WB_B.z() = vx * std::sin(u.gamma) / p.wheelbase;
  }
  out.w_eff_B = k.w_WB_B;
  k.w_WB_W = k.R_WB * k.w_WB_B;
}

void Suspension(const WheelParams& wp, const BodyKinematics& k, const TraceHit& hit,
                WheelOutputs& o) {
  if (!o.contact) {
    // In the air: the wheel hangs at the free length and every force is zero.
    o.Fp = o.Fh = o.Fb = o.Fy = o.Frr = 0.0;
    o.lS = wp.free_length;
    o.lT = 0.0;
    o.lS_rate = o.slip_angle = o.v_long = o.v_lat = 0.0;
    o.p_B_W = o.p_A_W + (wp.free_length + wp.radius) * k.down_W;
    o.n_W = Eigen::Vector3d::UnitZ();
    o.F_W.setZero();
    return;
  }
  const double d_AB = hit.distance;
  const Eigen::Vector3d& n_W = hit.normal_W;
  o.n_W = n_W;
  o.p_B_W = o.p_A_W + d_AB * k.down_W;
  o.lS = d_AB - wp.radius;
  o.lT = wp.free_length - o.lS;
  // Rate of AB for a ray from A along u = -Z_B to the fixed terrain plane (n, B):
  //   AB = (B - A).n / (u.n)   =>   d(AB)/dt = (-(v_A.n) - AB (w x u).n) / (u.n)
  const Eigen::Vector3d v_A = k.v_WT_W + k.w_WB_W.cross(o.p_A_W - k.p_WT_W);
  const double un = std::min(k.down_W.dot(n_W), -0.2);  // n faces A, so u.n < 0; guard grazing
  o.lS_rate = (-v_A.dot(n_W) - d_AB * k.w_WB_W.cross(k.down_W).dot(n_W)) / un;
  double spring = wp.spring_stiffness * o.lT;
  if (o.lS < wp.bump_stop_length) spring += wp.bump_stop_stiffness * (wp.bump_stop_length - o.lS);
  o.Fp = std::max(0.0, spring - wp.damper_coefficient * o.lS_rate);
}

void TireForces(const Params& p, const AppliedControl& u, int w, const BodyKinematics& k,
                bool report_all, WheelOutputs& o) {
  if (!o.contact) return;  // Suspension() zeroed every force of a wheel in the air
  const WheelParams& wp = p.wheel[w];
  const Eigen::Vector3d& n_W = o.n_W;
  const Eigen::Vector3d heading_W =
      u.cos_gamma_W[w] * k.R_WB.col(0) + u.sin_gamma_W[w] * k.R_WB.col(1);
  Eigen::Vector3d t_long = heading_W - heading_W.dot(n_W) * n_W;
  const double t_norm = t_long.norm();
  t_long = t_norm > 1e-9 ? Eigen::Vector3d(t_long / t_norm) : k.R_WB.col(0);
  const Eigen::Vector3d t_lat = n_W.cross(t_long);
  const Eigen::Vector3d v_B = k.v_WT_W + k.w_WB_W.cross(o.p_B_W - k.p_WT_W);
  o.v_long = v_B.dot(t_long);
  o.v_lat = v_B.dot(t_lat);
  // tan(slip angle), the slip angle regularised below tire_slip_speed; the angle itself only
  // where it is reported (it costs an atan).
  const double tan_alpha = o.v_lat / std::max(std::abs(o.v_long), p.tire_slip_speed);
  o.slip_angle = report_all ? std::atan(tan_alpha) : 0.0;
  double Fy = TireLateralForce(p.tire_law, tan_alpha, wp.cornering_stiffness, p.mu, o.Fp);
  const double roll_sign = SoftSign(o.v_long, 0.1 * p.tire_slip_speed);
  double Fh = u.drive_W[w];
  double Fb = u.brake_W[w] * roll_sign;  // opposes rolling; fades out at standstill
  double Frr = p.rolling_resistance * o.Fp * roll_sign;
  // Friction circle: the tangential force never exceeds mu * Fp.
  double Fx = Fh - Fb - Frr;
  const double f_max = p.mu * o.Fp;
  const double mag2 = Fx * Fx + Fy * Fy;
  if (mag2 > f_max * f_max) {
    const double s = f_max / std::sqrt(mag2);
    Fx *= s;
    Fy *= s;
    Fh *= s;
    Fb *= s;
    Frr *= s;
  }
  o.Fh = Fh;
  o.Fb = std::abs(Fb);
  o.Frr = std::abs(Frr);
  o.Fy = Fy;
  // The spring force is the normal force (the paper): it acts along the terrain normal at B.
  o.F_W = o.Fp * n_W + Fx * t_long + Fy * t_lat;
}

BodyLoads BodyForces(const Params& p, const WallPlanes& walls, const BodyKinematics& k,
                     Derived& out) {
  BodyLoads l;
  l.F_W = Eigen::Vector3d(0.0, 0.0, -p.mass * p.gravity);  // gravity G
  l.M_W = Eigen::Vector3d::Zero();                         // about T
  for (int w = 0; w < kNumWheels; ++w) {
    const WheelOutputs& o = out.wheel[w];
    if (!o.contact) continue;
    l.F_W += o.F_W;
    l.M_W += (o.p_B_W - k.p_WT_W).cross(o.F_W);
  }

  // Aligning torque at the hand wheel: the front side forces act `trail` behind the steering
  // axis and turn the wheels back towards straight ahead.
  out.steering_torque =
      -p.steering_trail * (out.wheel[kLF].Fy + out.wheel[kRF].Fy) / p.steering_ratio;

  // Drag at height ha above T.
  const double vx_B = k.R_WB.col(0).dot(k.v_WT_W);
  out.Da = 0.5 * p.rho * p.cx * p.sx * vx_B * std::abs(vx_B);  // eq. 15, signed to oppose vx
  l.F_W -= out.Da * k.R_WB.col(0);
  l.M_B = Eigen::Vector3d(0.0, -p.ha * out.Da, 0.0);  // (0, 0, ha) x (-Da, 0, 0)

  // Walls found by the horizontal traces, contact at each probe's end S.
  out.F_wall_W.setZero();
  out.wall_penetration_max = 0.0;
  out.wall_contacts = 0;
  for (int i = 0; i < Params::kNumProbes; ++i) {
    const WallPlane& wall = walls[i];
    if (!wall.active) continue;
    const Eigen::Vector3d p_S =
        k.p_WT_W + k.R_WB * (p.p_TO_B + p.probe_length[i] * p.probe_dir_B[i]);
    const double pen = (wall.p_W - p_S).dot(wall.n_W);
    if (pen <= 0.0) continue;
    const Eigen::Vector3d v_S = k.v_WT_W + k.w_WB_W.cross(p_S - k.p_WT_W);
    const double vn = v_S.dot(wall.n_W);
    // Hunt-Crossley contact: damping grows with penetration, so the force starts from zero at
    // first touch instead of jumping to c * v (Hunt & Crossley 1975, J. Appl. Mech. 42(2)).
    const double Fn = std::max(0.0, p.wall_stiffness * pen * (1.0 - p.wall_damping * vn));
    const Eigen::Vector3d v_t = v_S - vn * wall.n_W;
    const double vt = v_t.norm();
    Eigen::Vector3d F_c = Fn * wall.n_W;
    if (vt > 0.0) F_c -= (p.wall_friction * Fn * std::min(1.0, vt / 0.1) / vt) * v_t;
    l.F_W += F_c;
    l.M_W += (p_S - k.p_WT_W).cross(F_c);
    out.F_wall_W += F_c;
    out.wall_penetration_max = std::max(out.wall_penetration_max, pen);
    ++out.wall_contacts;
  }
  return l;
}

void Derivatives(const Params& p, const BodyKinematics& k, const BodyLoads& loads,
                 const StateVector& x, StateVector& xdot, Derived& out) {
  const Eigen::Vector3d& w_B = k.w_WB_B;
  Eigen::Vector3d M_B = loads.M_B;
  M_B += k.R_WB.transpose() * loads.M_W;
  out.F_W = loads.F_W;
  out.M_B = M_B;
  out.a_WT_W = loads.F_W / p.mass;
  const Eigen::Vector3d& I = p.inertia_B;
  // Euler: I dw/dt = M - w x (I w)  (principal axes)
  out.dw_B = (M_B - w_B.cross(I.cwiseProduct(w_B))).cwiseQuotient(I);
  if (k.paper_yaw) out.dw_B.z() = 0.0;  // yaw rate is imposed, not integrated

  xdot.segment<3>(sx::kP) = k.v_WT_W;
  // q' = 1/2 q (x) (0, w_B)
  const double qw = x[sx::kQ], qx = x[sx::kQ + 1], qy = x[sx::kQ + 2], qz = x[sx::kQ + 3];
  xdot[sx::kQ + 0] = 0.5 * (-qx * w_B.x() - qy * w_B.y() - qz * w_B.z());
  xdot[sx::kQ + 1] = 0.5 * (qw * w_B.x() + qy * w_B.z() - qz * w_B.y());
  xdot[sx::kQ + 2] = 0.5 * (qw * w_B.y() + qz * w_B.x() - qx * w_B.z());
  xdot[sx::kQ + 3] = 0.5 * (qw * w_B.z() + qx * w_B.y() - qy * w_B.x());
  xdot.segment<3>(sx::kV) = out.a_WT_W;
  xdot.segment<3>(sx::kW) = out.dw_B;
}

[[gnu::flatten]] void EvaluateDerivative(const Params& p, const Terrain& terrain, const AppliedControl& u,
                        const WallPlanes& walls, const StateVector& x, StateVector& xdot,
                        Derived& out, bool report_all) {
  BodyKinematics k;
  std::array<TraceHit, kNumWheels> hits;
  SenseTerrain(p, terrain, u, x, k, hits, out);
  for (int w = 0; w < kNumWheels; ++w) {
    out.wheel[w].gamma = u.gamma_W[w];
    Suspension(p.wheel[w], k, hits[w], out.wheel[w]);
    TireForces(p, u, w, k, report_all, out.wheel[w]);
  }
  const BodyLoads loads = BodyForces(p, walls, k, out);
  Derivatives(p, k, loads, x, xdot, out);
  xdot.tail<kStateSize - kPaperStateSize>().setZero();  // the full model's numbers stay put
}

}  // namespace vdyn
