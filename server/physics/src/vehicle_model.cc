#include "vdyn/physics/vehicle_model.h"

#include "vdyn/physics/full_model.h"
#include "vdyn/physics/magic_formula.h"

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
      u.wheel_cos_gamma[w] * k.R_WB.col(0) + u.wheel_sin_gamma[w] * k.R_WB.col(1);
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
  double Fh = u.wheel_drive[w];
  double Fb = u.wheel_brake[w] * roll_sign;  // opposes rolling; fades out at standstill
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
    // Bounded: however deep a probe is, the contact pushes with at most k_w times
    // kWallPenetrationCap, so no contact can inject unbounded energy.
    const double Fn = std::clamp(p.wall_stiffness * pen * (1.0 - p.wall_damping * vn), 0.0,
                                 p.wall_stiffness * kWallPenetrationCap);
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
    out.wheel[w].gamma = u.wheel_gamma[w];
    Suspension(p.wheel[w], k, hits[w], out.wheel[w]);
    TireForces(p, u, w, k, report_all, out.wheel[w]);
  }
  const BodyLoads loads = BodyForces(p, walls, k, out);
  Derivatives(p, k, loads, x, xdot, out);
  xdot.tail<kStateSize - kPaperStateSize>().setZero();  // the full model's numbers stay put
}


// === The full model's stages (docs/model.md, "The full model"; full_model.h lists them) ==========
// In this file with the paper's stages so that EvaluateDerivativeFull, like EvaluateDerivative,
// inlines every stage (BodyForces and Derivatives are shared).
namespace {

// Constants of the full model's equations (docs/model.md lists them with the parameters).
constexpr double kLowSpeed = 3.0;             // m/s: the contact patch's low-speed damping is gone
constexpr double kAirRelaxTime = 0.01;        // s: the tread of a wheel in the air springs back
constexpr double kRollingSpeed = 0.1;         // m/s: rolling resistance reaches its full value
constexpr double kSlipSpeedFloor = 1.0;       // m/s: floor of the reported slip ratio's denominator
constexpr double kColumnFrictionRate = 0.05;  // rad/s: column friction reaches its full value
constexpr double kEndStopHz = 30.0;           // hand-wheel end stops: frequency on the column
constexpr double kEndStopDampingRatio = 0.7;
constexpr double kRetraceOffset = 1e-3;       // m off a steep face before tracing on past it
constexpr double kGovernorBand = 0.1;         // of idle speed: the idle governor's band
constexpr double kLimiterBand = 0.02;         // of the rev limit: the limiter's band
constexpr double kStickSlipRateMax = 500.0;   // 1/s: a friction element's fastest break-away
constexpr double kSlidePullRate = 200.0;       // 1/s: a deflection past the peaks back, at rest

double Sgn(double v) { return static_cast<double>((v > 0.0) - (v < 0.0)); }

double SmoothStep01(double t) {
  t = std::clamp(t, 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

// LuGre friction with a constant Coulomb level (Canudas de Wit et al., IEEE TAC 40(3), 1995), in
// a normalised state s = sigma0 z / capacity: ds/dt = (dw - s |dw|) / angle, torque =
// capacity (s + damping_time ds/dt). A stuck element is a spring of stiffness capacity / angle,
// a sliding one transmits the capacity: it holds without creeping. The bristles' saturation rate
// |dw| / angle grows with the slip speed; above kStickSlipRateMax it is held there (the angle
// grows instead), which keeps the sliding state's equation inside RK4's stable range while a
// stuck element keeps its full stiffness.
struct StickSlip {
  double rate;
  double torque;
};
StickSlip LuGre(double s, double dw, double capacity, double angle, double damping_time) {
  const double abs_dw = std::abs(dw);
  const double rate = (dw - s * abs_dw) / std::max(angle, abs_dw / kStickSlipRateMax);
  return {rate, capacity * (s + damping_time * rate)};
}

// --- Stages -------------------------------------------------------------------------------------

// 1. Body kinematics and the vertical trace per wheel. A trace that hits a steep face (the side
//    of a kerb) goes on past it: a vertical face is never taken for ground.
void SenseTerrainFull(const Params& p, const Terrain& terrain, const StateVector& x,
                      BodyKinematics& k, std::array<TraceHit, kNumWheels>& hits, Derived& out) {
  k.R_WB = Orientation(x).normalized().toRotationMatrix();
  k.p_WT_W = Position(x);
  k.v_WT_W = Velocity(x);
  k.down_W = -k.R_WB.col(2);
  std::array<Eigen::Vector3d, kNumWheels> origins, dirs;
  std::array<double, kNumWheels> ranges;
  for (int w = 0; w < kNumWheels; ++w) {
    const WheelParams& wp = p.wheel[w];
    WheelOutputs& o = out.wheel[w];
    o.p_A_W = k.p_WT_W + k.R_WB * p.p_TA_B[w];
    origins[w] = o.p_A_W - wp.radius * k.down_W;  // lifted by R, as the paper's model
    dirs[w] = k.down_W;
    ranges[w] = 2.0 * wp.radius + wp.max_length;
  }
  terrain.Trace4(origins, dirs, ranges, hits);
  out.any_contact = false;
  for (int w = 0; w < kNumWheels; ++w) {
    TraceHit& hit = hits[w];
    for (int again = 0; again < 2 && hit.hit && -k.down_W.dot(hit.normal_W) < Terrain::kSteepNormalZ;
         ++again) {
      const Eigen::Vector3d from = origins[w] + hit.distance * k.down_W + kRetraceOffset * hit.normal_W;
      const double done = (from - origins[w]).dot(k.down_W);
      const TraceHit past = terrain.Trace(from, k.down_W, ranges[w] - done);
      hit = past;
      if (hit.hit) hit.distance += done;
    }
    if (hit.hit && -k.down_W.dot(hit.normal_W) < Terrain::kSteepNormalZ) hit.hit = false;
    if (hit.hit) hit.distance -= p.wheel[w].radius;  // now AB from A
  }
  k.w_WB_B = AngularVelocityB(x);
  k.paper_yaw = false;
  out.w_eff_B = k.w_WB_B;
  k.w_WB_W = k.R_WB * k.w_WB_B;
}

// 3. The tire's normal load and the spring length's rate. The tire is a radial spring k_t
//    around the wheel centre C = A + l_s u; it presses on the ground plane found by the trace and
//    on the kerb edges found by the C-D traces. The wheel is massless: the spring, bump stop and
//    damper carry what the tire pushes along the strut, so dl_s/dt = (F_spring - F_tire,u) / c,
//    stopped at the ends of travel.
void SuspensionFull(const Params& p, int w, const BodyKinematics& k, const TraceHit& hit,
                    const std::array<WheelEdge, 2>& edges, double l_s, WheelOutputs& o,
                    double& l_s_rate) {
  const WheelParams& wp = p.wheel[w];
  const Eigen::Vector3d& u = k.down_W;
  const Eigen::Vector3d C = o.p_A_W + l_s * u;  // wheel centre
  Eigen::Vector3d N = Eigen::Vector3d::Zero();
  Eigen::Vector3d B_sum = Eigen::Vector3d::Zero();
  double pen_sum = 0.0;
  o.kerb = false;
  if (hit.hit) {
    const Eigen::Vector3d& n = hit.normal_W;
    const Eigen::Vector3d B_g = o.p_A_W + hit.distance * u;  // the ground plane's point under A
    const double dist = (C - B_g).dot(n);
    const double pen = wp.radius - dist;
    if (pen > 0.0) {
      N += pen * n;
      B_sum += pen * (C - dist * n);
      pen_sum += pen;
    }
  }
  for (const WheelEdge& e : edges) {
    if (!e.active) continue;
    const Eigen::Vector3d r = C - e.p_E_W;
    const double d = r.norm();
    const double pen = wp.radius - d;
    if (pen > 0.0 && d > 1e-9) {
      N += (pen / d) * r;
      B_sum += pen * e.p_E_W;
      pen_sum += pen;
      o.kerb = true;
    }
  }
  N *= p.full.tire_vertical_stiffness[w];
  const double Fz = N.norm();
  o.contact = pen_sum > 0.0 && Fz > 0.0;
  if (o.contact) {
    o.n_W = N / Fz;
    o.p_B_W = B_sum / pen_sum;
  } else {
    o.n_W = -u;
    o.p_B_W = C + wp.radius * u;
  }
  o.Fp = o.contact ? Fz : 0.0;
  double F_spring = wp.spring_stiffness * (wp.free_length - l_s);
  if (l_s < wp.bump_stop_length) F_spring += wp.bump_stop_stiffness * (wp.bump_stop_length - l_s);
  const double F_tire_u = -N.dot(u);  // the tire pushing the wheel up the strut
  l_s_rate = (F_spring - F_tire_u) / wp.damper_coefficient;
  if (l_s <= wp.min_length && l_s_rate < 0.0) l_s_rate = 0.0;  // end of travel
  if (l_s >= wp.max_length && l_s_rate > 0.0) l_s_rate = 0.0;  // rebound stop
  o.lS = l_s;
  o.lT = wp.free_length - l_s;
  o.lS_rate = l_s_rate;
}

// 4b. The Magic Formula tyre (docs/model.md, 8.2b): the same deflections (u, v) with the file's
//     load-dependent relaxation lengths, the low-speed damping as the brush law's, the MF 6.1 law
//     at the transient slips and the wheel's inclination, the sliding limit at low speed.
void TireForcesMagicFormula(const Params& p, int w, const BodyKinematics& k,
                            const Eigen::Vector3d& lateral_W, const Eigen::Vector3d& t_long,
                            const Eigen::Vector3d& t_lat, double defl_u, double defl_v,
                            double v_slip, bool report_all, WheelOutputs& o, double& du,
                            double& dv) {
  const WheelParams& wp = p.wheel[w];
  const MagicFormula& m = wp.mf;
  const double speed = std::abs(o.v_long);
  // Inclination to the ground: the wheel's spin axis (its left, after the static camber: minus
  // camber on the left, plus on the right, so that negative camber leans the top inboard) against
  // the contact normal; ISO-W: positive leans the top to the right.
  const bool left = w == kLF || w == kLR;
  const Eigen::Vector3d axle_W =
      p.full.camber_cos[w] * lateral_W + p.full.camber_sin[w] * k.R_WB.col(2);
  const double gamma = std::asin(std::clamp(axle_W.dot(o.n_W), -1.0, 1.0));
  // A tyre on the other side than its file's TYRESIDE is mirrored (TNO's convention).
  const double mirror = (m.side == 0 || m.side == (left ? 1 : -1)) ? 1.0 : -1.0;
  const MfLoad load = MagicFormulaLoad(m, o.contact ? o.Fp : 0.0, mirror * gamma, m.inflpres);
  const double sigma_kappa = std::max(load.sigma_kappa, kMfMinRelaxationLength);
  const double sigma_alpha = std::max(load.sigma_alpha, kMfMinRelaxationLength);
  const double kappa_t = defl_u / sigma_kappa;
  const double tan_alpha_t = defl_v / sigma_alpha;
  if (report_all) {
    o.slip_ratio = v_slip / std::max(speed, kSlipSpeedFloor);
    o.slip_ratio_t = kappa_t;
    o.slip_angle_t = std::atan(tan_alpha_t);
    o.slip_angle = std::atan(o.v_lat / std::max(speed, kSlipSpeedFloor));
    o.camber = gamma;
    o.pressure = m.inflpres;
    o.kappa_law = o.alpha_law = 0.0;
  }
  if (!o.contact) {
    o.Fx = o.Fy = o.Mz = o.Mx = o.My = 0.0;
    o.F_W.setZero();
    du = -defl_u / kAirRelaxTime;
    dv = -defl_v / kAirRelaxTime;
    return;
  }
  // Low-speed damping of the patch, as the brush law's (faded out by kLowSpeed).
  const double fade = std::max(0.0, 1.0 - speed / kLowSpeed);
  const double damp = p.tire_low_speed_damping * fade * fade;
  const double kappa = kappa_t + damp * v_slip / std::max(load.Kxk, 1.0);
  const double tan_alpha = tan_alpha_t + damp * o.v_lat / std::max(std::abs(load.Kya), 1.0);
  const double Vc = std::sqrt(o.v_long * o.v_long + o.v_lat * o.v_lat);
  const MfOutput f =
      EvaluateMagicFormula(m, load, {kappa, mirror * tan_alpha, o.v_long, Vc},
                           /*aligning=*/report_all || w == kLF || w == kRF, report_all);
  o.Fx = f.Fx;
  o.Fy = mirror * f.Fy;
  o.Mz = mirror * f.Mz;
  o.My = f.My;
  if (report_all) {
    o.kappa_law = kappa;
    o.alpha_law = std::atan(tan_alpha);
    o.Mx = mirror * f.Mx;
  }
  o.F_W = o.Fp * o.n_W + o.Fx * t_long + o.Fy * t_lat;

  // Relaxation (as the brush law's) with the file's relaxation lengths. At low speed (where a
  // deflection would otherwise grow without bound, and stay wound up when the car stops) the patch
  // slides once its deflection carries the peak force on the carcass stiffness (slide >= 1): the
  // outward part of the rate is removed and the deflection pulled back to that limit, both faded
  // in below kLowSpeed, so that at speed the whole curve is followed.
  du = v_slip - speed * defl_u / sigma_kappa;
  dv = o.v_lat - speed * defl_v / sigma_alpha;
  const double hold = fade;
  if (f.slide > 1.0 && hold > 0.0) {
    const double kx = std::max(load.Kxk, 1.0) / sigma_kappa;
    const double ky = std::max(std::abs(load.Kya), 1.0) / sigma_alpha;
    const double wx = kx * defl_u, wy = ky * defl_v;
    const double wn = std::sqrt(wx * wx + wy * wy);
    if (wn > 0.0) {
      const double ex = wx / wn, ey = wy / wn;
      const double radial = ex * kx * du + ey * ky * dv;
      if (radial > 0.0) {
        du -= hold * radial * ex / kx;
        dv -= hold * radial * ey / ky;
      }
      const double pull = hold * kSlidePullRate * (1.0 - 1.0 / f.slide);
      du -= pull * defl_u;
      dv -= pull * defl_v;
    }
  }
}

// 4. Tire forces: transient slips from the contact patch's deflections (u, v), the brush law
//    with combined slip, the aligning moment, and the deflections' rates (relaxation lengths).
void TireForcesFull(const Params& p, int w, const BodyKinematics& k, double cos_g, double sin_g,
                    const StateVector& x, bool report_all, WheelOutputs& o, double& du, double& dv) {
  const WheelParams& wp = p.wheel[w];
  const double defl_u = x[sx::kDeflectionLong + w];
  const double defl_v = x[sx::kDeflectionLat + w];
  const double omega = x[sx::kWheelSpin + w];
  o.omega = omega;
  const Eigen::Vector3d heading_W = cos_g * k.R_WB.col(0) + sin_g * k.R_WB.col(1);
  const Eigen::Vector3d& n_W = o.n_W;
  Eigen::Vector3d t_long = heading_W - heading_W.dot(n_W) * n_W;
  const double t_norm = t_long.norm();
  t_long = t_norm > 1e-9 ? Eigen::Vector3d(t_long / t_norm) : k.R_WB.col(0);
  const Eigen::Vector3d t_lat = n_W.cross(t_long);
  const Eigen::Vector3d v_B = k.v_WT_W + k.w_WB_W.cross(o.p_B_W - k.p_WT_W);
  o.v_long = v_B.dot(t_long);
  o.v_lat = v_B.dot(t_lat);
  const double v_slip = omega * wp.radius - o.v_long;  // longitudinal slip velocity
  const double speed = std::abs(o.v_long);
  if (wp.mf.enabled) {
    const Eigen::Vector3d lateral_W = -sin_g * k.R_WB.col(0) + cos_g * k.R_WB.col(1);
    TireForcesMagicFormula(p, w, k, lateral_W, t_long, t_lat, defl_u, defl_v, v_slip, report_all, o,
                           du, dv);
    return;
  }
  if (report_all) {
    o.camber = o.pressure = o.Mx = 0.0;  // the brush law reads no camber and no pressure
    o.kappa_law = o.alpha_law = 0.0;
  }
  const double kappa_t = defl_u / p.tire_relaxation_long;
  const double tan_alpha_t = defl_v / p.tire_relaxation_lat;
  if (report_all) {
    o.slip_ratio = v_slip / std::max(speed, kSlipSpeedFloor);
    o.slip_ratio_t = kappa_t;
    o.slip_angle_t = std::atan(tan_alpha_t);
    o.slip_angle = std::atan(o.v_lat / std::max(speed, kSlipSpeedFloor));
  }
  if (!o.contact) {
    o.Fx = o.Fy = o.Mz = 0.0;
    o.F_W.setZero();
    du = -defl_u / kAirRelaxTime;
    dv = -defl_v / kAirRelaxTime;
    return;
  }
  const double Fz = o.Fp;
  const double load = Fz / wp.nominal_load;
  const double C_kappa = wp.longitudinal_stiffness * load;
  const double C_alpha = CorneringStiffnessAt(p, w, Fz);
  // Low-speed damping of the patch (Pacejka's k_Vlow): a damper on the slip velocities that
  // fades out by kLowSpeed; it settles a standing car and is zero once it stands.
  const double fade = std::max(0.0, 1.0 - speed / kLowSpeed);
  const double damp = p.tire_low_speed_damping * fade * fade;
  const double phi_x = C_kappa * kappa_t + damp * v_slip;
  const double phi_y = C_alpha * tan_alpha_t + damp * o.v_lat;
  if (report_all) {
    o.kappa_law = phi_x / C_kappa;
    o.alpha_law = std::atan(phi_y / C_alpha);
  }
  const double mu0 = p.full.mu_static;
  const double force_max = 3.0 * mu0 * Fz;
  const double z = std::sqrt(phi_x * phi_x + phi_y * phi_y) / force_max;
  const double g = BrushForceRatio(z, mu0, p.full.mu_slide);
  o.Fx = g * phi_x;
  o.Fy = -g * phi_y;
  const double a = p.tire_contact_half_length * std::sqrt(load);
  o.Mz = -a * BrushTrailRatio(z, mu0, p.full.mu_slide) * o.Fy;
  o.F_W = Fz * n_W + o.Fx * t_long + o.Fy * t_lat;

  // Relaxation: sigma du/dt... as deflections: du/dt = V_slip - |V| u / sigma_long,
  // dv/dt = V_lat - |V| v / sigma_lat. In full sliding (z of the deflections >= 1) the patch
  // slides instead of deflecting further: the outward part of the rate is removed, so the
  // deflection turns with the slip without growing.
  du = v_slip - speed * defl_u / p.tire_relaxation_long;
  dv = o.v_lat - speed * defl_v / p.tire_relaxation_lat;
  const double wx = C_kappa * kappa_t, wy = C_alpha * tan_alpha_t;
  const double wn = std::sqrt(wx * wx + wy * wy);
  if (wn >= force_max && wn > 0.0) {
    const double kx = C_kappa / p.tire_relaxation_long, ky = C_alpha / p.tire_relaxation_lat;
    const double ex = wx / wn, ey = wy / wn;
    const double radial = ex * kx * du + ey * ky * dv;
    if (radial > 0.0) {
      du -= radial * ex / kx;
      dv -= radial * ey / ky;
    }
  }
}

// 5. Drivetrain: engine, clutch (LuGre), gearbox and differentials, brakes (LuGre), rolling
//    resistance; the spin rates of the wheels and the engine.
void DrivetrainFull(const Params& p, const AppliedControl& u, const StateVector& x, Derived& out,
                    StateVector& xdot) {
  const Params::Derived& d = p.full;
  const double w_e = x[sx::kEngine];
  const double w_out = GearboxOutputSpeed(p, x);
  const double w_in = u.gearbox_ratio * w_out;
  // Engine: full-load torque from P = P_max (r + r^2 - r^3), engine braking at closed throttle,
  // an idle governor and a rev limiter acting on the throttle.
  const double r = std::max(w_e, 0.0) / d.omega_power;
  const double full_load = std::max(0.0, d.engine_torque_base * (1.0 + r - r * r));
  const double drag = p.engine_brake_torque * std::max(w_e, 0.0) / d.omega_limit;
  const double governor = std::clamp((d.omega_idle - w_e) / (kGovernorBand * d.omega_idle), 0.0, 1.0);
  const double limiter = std::clamp((d.omega_limit - w_e) / (kLimiterBand * d.omega_limit), 0.0, 1.0);
  const double throttle = std::max(u.pedal * limiter, governor);
  const double T_engine = throttle * full_load - (1.0 - throttle) * drag;
  // Clutch: the pedal and the shift open it; the automatic clutch engages with engine speed.
  const double engage = SmoothStep01((w_e - d.omega_idle) / (d.omega_engage - d.omega_idle));
  const double capacity = u.gearbox_ratio != 0.0 ? p.clutch_torque_max * u.clutch_engagement * engage : 0.0;
  const double slip = w_e - w_in;
  const StickSlip clutch = LuGre(x[sx::kClutch], slip, capacity, p.clutch_stick_angle, p.stick_damping_time);
  xdot[sx::kClutch] = clutch.rate;
  xdot[sx::kEngine] = (T_engine - clutch.torque) / p.engine_inertia;
  out.drivetrain.engine_speed = w_e;
  out.drivetrain.engine_torque = T_engine;
  out.drivetrain.throttle = throttle;
  out.drivetrain.clutch_torque = clutch.torque;
  out.drivetrain.clutch_slip = slip;

  std::array<double, kNumWheels> net{};
  for (int w = 0; w < kNumWheels; ++w) {
    const WheelParams& wp = p.wheel[w];
    WheelOutputs& o = out.wheel[w];
    const double omega = x[sx::kWheelSpin + w];
    const double T_drive = p.drivetrain_efficiency * u.gearbox_ratio * d.drive_share[w] * clutch.torque;
    const StickSlip brake = LuGre(x[sx::kBrake + w], omega, u.wheel_brake_torque[w],
                                  p.brake_stick_angle, p.stick_damping_time);
    xdot[sx::kBrake + w] = brake.rate;
    // Rolling resistance: f_rr Fz R, or a Magic Formula tyre's |My|, against the rolling.
    const double T_rr = wp.mf.enabled ? std::abs(o.My) : p.rolling_resistance * o.Fp * wp.radius;
    const double T_roll =
        o.contact ? T_rr * std::clamp(omega * wp.radius / kRollingSpeed, -1.0, 1.0) : 0.0;
    net[w] = T_drive - brake.torque - wp.radius * o.Fx - T_roll;
    o.drive_torque = T_drive;
    o.brake_torque = std::abs(brake.torque);
    o.Fh = T_drive / wp.radius;
    o.Fb = o.brake_torque / wp.radius;
    o.Frr = std::abs(T_roll) / wp.radius;
    o.My = -T_roll;
  }
  for (int w = 0; w < kNumWheels; ++w) xdot[sx::kWheelSpin + w] = net[w] / p.wheel[w].spin_inertia;
  if (p.differential == Differential::kLocked) {
    // A locked axle differential: both wheels of a driven axle share one spin rate.
    for (int left : {kLF, kLR}) {
      const int right = left + 1;
      if (d.drive_share[left] <= 0.0) continue;
      const double a = (net[left] + net[right]) /
                       (p.wheel[left].spin_inertia + p.wheel[right].spin_inertia);
      xdot[sx::kWheelSpin + left] = a;
      xdot[sx::kWheelSpin + right] = a;
    }
  }
}

// 6. Steering column: the front tires' moments about their steering axes, brought to the hand
//    wheel by the steering geometry, with the column's friction, damping and end stops. With the
//    hands on, the column follows the commanded angle (a critically damped follower) and the
//    driver's torque is what that takes; with the hands off it turns under these torques alone.
void SteeringColumnFull(const Params& p, const AppliedControl& u, const StateVector& x,
                        const FrontWheelAngles& geom, Derived& out, StateVector& xdot) {
  const double angle = x[sx::kHandWheel];
  const double rate = x[sx::kHandWheelRate];
  Derived::Steering& s = out.steering;
  s.angle = angle;
  s.rate = rate;
  s.aligning = s.trail = 0.0;
  for (int w : {kLF, kRF}) {
    const WheelOutputs& o = out.wheel[w];
    if (!o.contact) continue;
    // Moment about the steering axis, which meets the ground caster_trail ahead of B and
    // scrub_radius inboard: (B - K) x F = -t_c Fy - (+-r_s) Fx (+ for the left wheel).
    const double side = w == kLF ? 1.0 : -1.0;
    const double lever = geom.dgamma_ddelta[w] / p.steering_ratio;
    s.aligning += o.Mz * lever;
    s.trail += (-p.caster_trail * o.Fy - side * p.scrub_radius * o.Fx) * lever;
  }
  s.friction = -p.steering_friction * std::clamp(rate / kColumnFrictionRate, -1.0, 1.0);
  s.damping = -p.steering_damping * rate;
  s.end_stop = 0.0;
  const double over = std::abs(angle) - p.full.hand_wheel_lock;
  if (over > 0.0) {
    const double k_stop = p.steering_inertia * (2.0 * 3.14159265358979323846 * kEndStopHz) *
                          (2.0 * 3.14159265358979323846 * kEndStopHz);
    const double d_stop = 2.0 * kEndStopDampingRatio * std::sqrt(k_stop * p.steering_inertia);
    s.end_stop = -Sgn(angle) * k_stop * over - d_stop * rate;
  }
  const double system = s.aligning + s.trail + s.friction + s.damping + s.end_stop;
  out.steering_torque = system;
  double accel;
  if (u.hands_on) {
    const double f = p.steering_follow_frequency;
    accel = f * f * (u.hand_wheel_target - angle) - 2.0 * f * rate;
    s.driver = p.steering_inertia * accel - system;
  } else {
    accel = system / p.steering_inertia;
    s.driver = 0.0;
  }
  xdot[sx::kHandWheel] = rate;
  xdot[sx::kHandWheelRate] = accel;
}

}  // namespace

[[gnu::flatten]] void EvaluateDerivativeFull(const Params& p, const Terrain& terrain,
                                             const AppliedControl& u, const WallPlanes& walls,
                                             const WheelEdges& edges, const StateVector& x,
                                             StateVector& xdot, Derived& out, bool report_all) {
  BodyKinematics k;
  std::array<TraceHit, kNumWheels> hits;
  SenseTerrainFull(p, terrain, x, k, hits, out);
  const FrontWheelAngles geom = SteeringGeometry(p, x[sx::kHandWheel]);
  for (int w = 0; w < kNumWheels; ++w) {
    WheelOutputs& o = out.wheel[w];
    const double c = IsFront(w) ? geom.cos_gamma[w] : 1.0;
    const double s = IsFront(w) ? geom.sin_gamma[w] : 0.0;
    if (report_all) o.gamma = std::atan2(s, c);
    SuspensionFull(p, w, k, hits[w], edges.wheel[w], x[sx::kSpring + w], o, xdot[sx::kSpring + w]);
    out.any_contact = out.any_contact || o.contact;
    TireForcesFull(p, w, k, c, s, x, report_all, o, xdot[sx::kDeflectionLong + w],
                   xdot[sx::kDeflectionLat + w]);
  }
  DrivetrainFull(p, u, x, out, xdot);
  const BodyLoads loads = BodyForces(p, walls, k, out);
  Derivatives(p, k, loads, x, xdot, out);
  SteeringColumnFull(p, u, x, geom, out, xdot);
}

}  // namespace vdyn
