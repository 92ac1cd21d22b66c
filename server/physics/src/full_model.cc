#include "vdyn/physics/full_model.h"

#include <algorithm>
#include <cmath>

namespace vdyn {
namespace {

// Constants of the full model (docs/model.md lists them with the parameters).
constexpr double kLowSpeed = 3.0;             // m/s: the contact patch's low-speed damping is gone
constexpr double kAirRelaxTime = 0.01;        // s: the tread of a wheel in the air springs back
constexpr double kRollingSpeed = 0.1;         // m/s: rolling resistance reaches its full value
constexpr double kSlipSpeedFloor = 1.0;       // m/s: floor of the reported slip ratio's denominator
constexpr double kColumnFrictionRate = 0.05;  // rad/s: column friction reaches its full value
constexpr double kEndStopHz = 30.0;           // hand-wheel end stops: frequency on the column
constexpr double kEndStopDampingRatio = 0.7;
constexpr double kEdgeClearance = 0.015;      // m: the C-D traces run this far above the ground
constexpr double kEdgeReach = 0.1;            // m: ... and this far beyond the tire
constexpr double kMaxEdgeHeight = 0.6;        // wheel radii: a higher face is a wall, not a kerb
constexpr double kRetraceOffset = 1e-3;       // m off a steep face before tracing on past it
constexpr double kShiftDwell = 0.5;           // s from the end of a shift to the next
constexpr double kReverseSpeed = 1.0;         // m/s: the automatic changes direction below this
constexpr double kControlSpeed = 1.5;         // m/s: ABS acts above this; slip-ratio floor of TC
constexpr double kSlipTarget = 0.9;           // ABS and TC hold this fraction of the peak slip
constexpr double kAbsRelease = 40.0;          // 1/s per unit of excess slip
constexpr double kAbsApply = 20.0;            // 1/s per unit of missing slip
constexpr double kTcRelease = 20.0;           // 1/s per unit of excess slip
constexpr double kTcApply = 4.0;              // 1/s
constexpr double kGovernorBand = 0.1;         // of idle speed: the idle governor's band
constexpr double kLimiterBand = 0.02;         // of the rev limit: the limiter's band
constexpr double kMaxShiftClock = 10.0;       // s: the shift clock stops here
constexpr double kStickSlipRateMax = 500.0;   // 1/s: a friction element's fastest break-away

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

// Static spring length of wheel w carrying its share of the weight (bump stop included).
double StaticSpringLength(const Params& p, int w) {
  const WheelParams& wp = p.wheel[w];
  const double axle = IsFront(w) ? p.c / p.wheelbase : p.b / p.wheelbase;
  const bool left = w == kLF || w == kLR;
  const double side = left ? p.b_p / (p.b_l + p.b_p) : p.b_l / (p.b_l + p.b_p);
  const double F = p.mass * p.gravity * axle * side;
  double lT = F / wp.spring_stiffness;
  if (wp.free_length - lT < wp.bump_stop_length) {
    lT = (F + wp.bump_stop_stiffness * (wp.free_length - wp.bump_stop_length)) /
         (wp.spring_stiffness + wp.bump_stop_stiffness);
  }
  return std::clamp(wp.free_length - lT, wp.min_length, wp.max_length);
}

// The gearbox output speed per unit ratio: the drive-share-weighted wheel speeds (the open
// differentials' kinematics), rad/s.
double GearboxOutputSpeed(const Params& p, const StateVector& x) {
  double w = 0.0;
  for (int i = 0; i < kNumWheels; ++i) w += p.full.drive_share[i] * x[sx::kWheelSpin + i];
  return w;
}

double GearboxRatio(const Params& p, int gear) {
  if (gear > 0) return p.full.gear_ratio[gear] * p.final_drive_ratio;
  if (gear < 0) return -p.gear_ratio_reverse * p.final_drive_ratio;
  return 0.0;
}

// The forward gear the automatic picks from gear g at gearbox output speed w_out and pedal.
int AutomaticGear(const Params& p, int g, double w_out, double pedal) {
  const Params::Derived& d = p.full;
  const double w_engine = GearboxRatio(p, g) * w_out;
  // Upshift at shift_up_rpm at full pedal; at part pedal earlier, but never so early that the
  // next gear lands below 1.2 x shift_down_rpm.
  const double w_low = std::min(d.omega_shift_up, 1.2 * d.omega_shift_down / d.ratio_step);
  const double w_up = w_low + (d.omega_shift_up - w_low) * std::clamp(pedal, 0.0, 1.0);
  if (g < p.gear_count && w_engine > w_up) return g + 1;
  if (g > 1 && w_engine < d.omega_shift_down) return g - 1;
  return g;
}

// Per-wheel longitudinal velocity of the mount point along the wheel's heading, from the body
// motion alone (the controllers' view at the step start; no terrain).
std::array<double, kNumWheels> WheelSpeedsAlongHeading(const Params& p, const StateVector& x) {
  const Eigen::Matrix3d R_WB = Orientation(x).normalized().toRotationMatrix();
  const Eigen::Vector3d v_B = R_WB.transpose() * Velocity(x);
  const Eigen::Vector3d w_B = AngularVelocityB(x);
  const FrontWheelAngles g = SteeringGeometry(p, x[sx::kHandWheel]);
  std::array<double, kNumWheels> v{};
  for (int w = 0; w < kNumWheels; ++w) {
    const Eigen::Vector3d v_A = v_B + w_B.cross(p.p_TA_B[w]);
    const double c = IsFront(w) ? g.cos_gamma[w] : 1.0;
    const double s = IsFront(w) ? g.sin_gamma[w] : 0.0;
    v[w] = c * v_A.x() + s * v_A.y();
  }
  return v;
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
  N *= p.tire_vertical_stiffness;
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
    const StickSlip brake = LuGre(x[sx::kBrake + w], omega, u.brake_torque_W[w],
                                  p.brake_stick_angle, p.stick_damping_time);
    xdot[sx::kBrake + w] = brake.rate;
    const double T_roll = o.contact ? p.rolling_resistance * o.Fp * wp.radius *
                                          std::clamp(omega * wp.radius / kRollingSpeed, -1.0, 1.0)
                                    : 0.0;
    net[w] = T_drive - brake.torque - wp.radius * o.Fx - T_roll;
    o.drive_torque = T_drive;
    o.brake_torque = std::abs(brake.torque);
    o.Fh = T_drive / wp.radius;
    o.Fb = o.brake_torque / wp.radius;
    o.Frr = std::abs(T_roll) / wp.radius;
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

double BrushForceRatio(double z, double mu, double mu_slide) {
  if (z >= 1.0) return mu_slide / (3.0 * mu * z);
  const double q = 1.0 - z;
  return q * q + mu_slide / (3.0 * mu) * z * (3.0 - 2.0 * z);
}

double BrushTrailRatio(double z, double mu, double mu_slide) {
  if (z >= 1.0) return 0.0;
  const double q = 1.0 - z;
  return q * q * (mu * (1.0 - 4.0 * z) + 3.0 * mu_slide * z) /
         (3.0 * mu * q * q + mu_slide * z * (3.0 - 2.0 * z));
}

double CorneringStiffnessAt(const Params& p, int w, double Fz) {
  const WheelParams& wp = p.wheel[w];
  const double x = Fz / (p.tire_load_sensitivity * wp.nominal_load);
  return wp.cornering_stiffness * p.full.load_sensitivity_norm[w] * 2.0 * x / (1.0 + x * x);
}

FrontWheelAngles SteeringGeometry(const Params& p, double hand_wheel_angle) {
  FrontWheelAngles g;
  // The rack's angle delta (a virtual centre wheel); Ackermann: cot(gamma_L) = cot(delta) - k/L,
  // cot(gamma_R) = cot(delta) + k/L with k = ackermann * track / 2.
  const double delta = std::clamp(hand_wheel_angle / p.steering_ratio, -1.55, 1.55);
  const double t = std::tan(delta);
  const double L = p.wheelbase;
  const double num = L * t;
  for (int i = 0; i < 2; ++i) {
    const double den = i == 0 ? L - p.full.ackermann_offset * t : L + p.full.ackermann_offset * t;
    const double hyp2 = num * num + den * den;
    const double inv = 1.0 / std::sqrt(hyp2);
    g.cos_gamma[i] = den * inv;
    g.sin_gamma[i] = num * inv;
    g.dgamma_ddelta[i] = L * L * (1.0 + t * t) / hyp2;
  }
  return g;
}

bool FindWheelEdges(const Params& p, const Terrain& terrain, const StateVector& x,
                    WheelEdges& edges) {
  for (auto& we : edges.wheel) {
    for (WheelEdge& e : we) e.active = false;
  }
  const Eigen::Matrix3d R_WB = Orientation(x).normalized().toRotationMatrix();
  const Eigen::Vector3d p_WT = Position(x);
  const double reach = std::max(p.body_front, p.body_rear) + p.body_half_width + 1.0;
  if (!terrain.SteepSurfaceNear(p_WT.x(), p_WT.y(), reach)) return false;
  const Eigen::Vector3d down = -R_WB.col(2);
  const FrontWheelAngles geom = SteeringGeometry(p, x[sx::kHandWheel]);
  for (int w = 0; w < kNumWheels; ++w) {
    const WheelParams& wp = p.wheel[w];
    const Eigen::Vector3d A = p_WT + R_WB * p.p_TA_B[w];
    const Eigen::Vector3d from = A - wp.radius * down;
    const TraceHit ground = terrain.Trace(from, down, 2.0 * wp.radius + wp.max_length);
    if (!ground.hit || -down.dot(ground.normal_W) < Terrain::kSteepNormalZ) continue;
    const Eigen::Vector3d& n = ground.normal_W;
    const Eigen::Vector3d G = from + ground.distance * down;
    const double c = IsFront(w) ? geom.cos_gamma[w] : 1.0;
    const double s = IsFront(w) ? geom.sin_gamma[w] : 0.0;
    const Eigen::Vector3d heading = c * R_WB.col(0) + s * R_WB.col(1);
    Eigen::Vector3d along = heading - heading.dot(n) * n;
    if (along.norm() < 1e-9) continue;
    along.normalize();
    for (int side = 0; side < 2; ++side) {
      const Eigen::Vector3d dir = side == 0 ? along : Eigen::Vector3d(-along);
      const Eigen::Vector3d o = G + kEdgeClearance * n;
      const TraceHit face = terrain.Trace(o, dir, wp.radius + kEdgeReach);
      if (!face.hit || std::abs(face.normal_W.dot(n)) >= Terrain::kSteepNormalZ) continue;
      const Eigen::Vector3d D = o + face.distance * dir;
      // The face's top: trace down just beyond the face from the wheel centre's height.
      const Eigen::Vector3d top_from = D + 0.01 * dir + (wp.radius - kEdgeClearance) * n;
      const TraceHit top = terrain.Trace(top_from, -n, wp.radius);
      if (!top.hit || top.normal_W.dot(n) < Terrain::kSteepNormalZ) continue;
      const double height = (top_from - top.distance * n - G).dot(n);
      if (height <= kEdgeClearance || height > kMaxEdgeHeight * wp.radius) continue;
      WheelEdge& e = edges.wheel[w][side];
      e.active = true;
      e.p_E_W = D + (height - kEdgeClearance) * n;
    }
  }
  return true;
}

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

AppliedControl ComputeControlsFull(const Params& p, const DriverInput& in, double h, State& state) {
  AppliedControl u;
  const Params::Derived& d = p.full;
  DiscreteState& ds = state.discrete;
  const StateVector& x = state.x;

  // Steering: the angle the column follows (inside the steering lock), or hands off.
  u.hands_on = in.steer_mode != SteerMode::kHandsOff;
  switch (in.steer_mode) {
    case SteerMode::kRoadWheel:
      u.hand_wheel_target = std::clamp(in.steer, -p.steering_lock, p.steering_lock) * p.steering_ratio;
      break;
    case SteerMode::kHandWheel:
      u.hand_wheel_target = std::clamp(in.steer, -d.hand_wheel_lock, d.hand_wheel_lock);
      break;
    case SteerMode::kHandsOff:
      u.hand_wheel_target = x[sx::kHandWheel];
      break;
  }
  u.gamma = u.hand_wheel_target / p.steering_ratio;

  // Pedals and the speed control, as in the paper's model.
  u.throttle = in.throttle;
  u.brake = in.brake;
  CruiseControl(p, in, h, state, u);
  const Eigen::Matrix3d R_WB = Orientation(x).normalized().toRotationMatrix();
  const double vx = R_WB.col(0).dot(Velocity(x));
  const double w_out = GearboxOutputSpeed(p, x);

  // Direction and gear. Automatic (gear 0): a negative throttle asks for reverse; while the car
  // still rolls the other way faster than kReverseSpeed, the pedal brakes instead. A gear chosen
  // by the driver is engaged as asked; a negative throttle then brakes.
  u.automatic = in.gear == 0;
  double pedal = 0.0;
  double brake = u.brake;
  int target = ds.gear;
  ds.shift_time = std::min(ds.shift_time + h, kMaxShiftClock);
  const bool may_shift = ds.shift_time >= p.shift_time + kShiftDwell;
  if (u.automatic) {
    if (u.throttle < 0.0) {
      if (vx > kReverseSpeed) {
        brake = std::max(brake, -u.throttle);
      } else {
        pedal = -u.throttle;
        target = -1;
      }
    } else if (ds.gear < 0 && vx < -kReverseSpeed && u.throttle > 0.0) {
      brake = std::max(brake, u.throttle);
    } else {
      pedal = u.throttle;
      if (ds.gear <= 0) {
        target = 1;
      } else if (may_shift) {
        target = AutomaticGear(p, ds.gear, w_out, pedal);
      }
    }
  } else {
    target = std::clamp(in.gear, -1, p.gear_count);
    pedal = std::max(u.throttle, 0.0);
    if (u.throttle < 0.0) brake = std::max(brake, -u.throttle);
  }
  if (target != ds.gear) {
    ds.gear = target;
    ds.shift_time = 0.0;
  }
  u.gear = ds.gear;
  u.gearbox_ratio = GearboxRatio(p, ds.gear);
  u.shifting = ds.shift_time < p.shift_time;
  u.clutch_engagement = (u.gear == 0 || u.shifting) ? 0.0 : 1.0 - in.clutch;

  // Slip ratios at the step start, for ABS and traction control.
  const std::array<double, kNumWheels> v_long = WheelSpeedsAlongHeading(p, x);
  std::array<double, kNumWheels> kappa{};
  for (int w = 0; w < kNumWheels; ++w) {
    kappa[w] = (x[sx::kWheelSpin + w] * p.wheel[w].radius - v_long[w]) /
               std::max(std::abs(v_long[w]), kControlSpeed);
  }
  // Traction control: the largest driving slip of a driven wheel held near the tire's peak by
  // an integral action on the engine's torque.
  if (p.traction_control && pedal > 0.0) {
    const double dir = ds.gear < 0 ? -1.0 : 1.0;
    double excess = -1.0;
    for (int w = 0; w < kNumWheels; ++w) {
      if (d.drive_share[w] <= 0.0) continue;
      excess = std::max(excess, dir * kappa[w] / (kSlipTarget * d.peak_slip[w]) - 1.0);
    }
    excess = std::max(excess, -1.0);
    ds.tc = std::clamp(ds.tc + h * (excess > 0.0 ? -kTcRelease * excess : -kTcApply * excess),
                       0.0, 1.0);
  } else {
    ds.tc = 1.0;
  }
  u.pedal = u.shifting ? 0.0 : pedal * ds.tc;
  // For the record: the accelerator as the driver (or the speed control) applies it, signed by
  // the direction of travel; traction control and shifts act at the engine (Derived::drivetrain).
  const double accelerator = u.gear < 0 ? -pedal : pedal;

  // Brakes, with ABS: each wheel's braking slip held near the tire's peak by an integral action
  // on its brake pressure, above kControlSpeed.
  for (int w = 0; w < kNumWheels; ++w) {
    if (p.abs && brake > 0.0) {
      double excess = -1.0;
      if (std::abs(v_long[w]) > kControlSpeed) {
        excess = std::max(-Sgn(v_long[w]) * kappa[w] / (kSlipTarget * d.peak_slip[w]) - 1.0, -1.0);
      }
      ds.abs[w] = std::clamp(
          ds.abs[w] + h * (excess > 0.0 ? -kAbsRelease * excess : -kAbsApply * excess), 0.0, 1.0);
    } else {
      ds.abs[w] = 1.0;
    }
    u.brake_torque_W[w] = ds.abs[w] * brake * d.brake_torque[w] + in.handbrake * d.handbrake_torque[w];
    u.abs_factor[w] = ds.abs[w];
  }
  u.tc_factor = ds.tc;
  u.throttle = accelerator;
  u.brake = brake;

  // Road-wheel angles at the step start, for the record.
  const FrontWheelAngles geom = SteeringGeometry(p, x[sx::kHandWheel]);
  for (int w = 0; w < kNumWheels; ++w) {
    u.cos_gamma_W[w] = IsFront(w) ? geom.cos_gamma[w] : 1.0;
    u.sin_gamma_W[w] = IsFront(w) ? geom.sin_gamma[w] : 0.0;
    u.gamma_W[w] = std::atan2(u.sin_gamma_W[w], u.cos_gamma_W[w]);
    u.drive_W[w] = 0.0;
    u.brake_W[w] = u.brake_torque_W[w] / p.wheel[w].radius;
  }
  return u;
}

State InitFullState(const Params& p, const State& s) {
  State out = s;
  out.model = VehicleModel::kFull;
  out.x.tail<kStateSize - kPaperStateSize>().setZero();
  out.discrete = DiscreteState{};
  const Eigen::Matrix3d R_WB = Orientation(s.x).normalized().toRotationMatrix();
  const Eigen::Vector3d v_B = R_WB.transpose() * Velocity(s.x);
  const Eigen::Vector3d w_B = AngularVelocityB(s.x);
  for (int w = 0; w < kNumWheels; ++w) {
    const Eigen::Vector3d v_A = v_B + w_B.cross(p.p_TA_B[w]);
    out.x[sx::kWheelSpin + w] = v_A.x() / p.wheel[w].radius;  // rolling without slip
    out.x[sx::kSpring + w] = StaticSpringLength(p, w);
  }
  // The gear the automatic would be in at this speed (first at a standstill), the engine turning
  // with it (at least at idle), the clutch unloaded, the shift long over.
  const double w_out = GearboxOutputSpeed(p, out.x);
  int gear = 1;
  for (int i = 0; i < p.gear_count; ++i) {
    const int next = AutomaticGear(p, gear, w_out, 1.0);
    if (next <= gear) break;
    gear = next;
  }
  out.discrete.gear = gear;
  out.discrete.shift_time = kMaxShiftClock;
  out.x[sx::kEngine] = std::max(p.full.omega_idle, GearboxRatio(p, gear) * w_out);
  return out;
}

State ConvertState(const Params& p, const State& s) {
  if (s.model == p.model) return s;
  if (p.model == VehicleModel::kFull) return InitFullState(p, s);
  State out = s;
  out.model = VehicleModel::kPaper;
  out.x.tail<kStateSize - kPaperStateSize>().setZero();
  out.discrete = DiscreteState{};
  return out;
}

}  // namespace vdyn
