#include "vdyn/physics/full_model.h"

#include <algorithm>
#include <cmath>

namespace vdyn {
namespace {

// Constants of the full model's controllers and kerb traces (docs/model.md lists them).
constexpr double kEdgeClearance = 0.015;      // m: the C-D traces run this far above the ground
constexpr double kEdgeReach = 0.1;            // m: ... and this far beyond the tire
constexpr double kMaxEdgeHeight = 0.6;        // wheel radii: a higher face is a wall, not a kerb
constexpr double kShiftDwell = 0.5;           // s from the end of a shift to the next
constexpr double kReverseSpeed = 1.0;         // m/s: the automatic changes direction below this
constexpr double kControlSpeed = 1.5;         // m/s: ABS acts above this; slip-ratio floor of TC
constexpr double kSlipTarget = 0.9;           // ABS and TC hold this fraction of the peak slip
constexpr double kAbsRelease = 40.0;          // 1/s per unit of excess slip
constexpr double kAbsApply = 20.0;            // 1/s per unit of missing slip
constexpr double kTcRelease = 20.0;           // 1/s per unit of excess slip
constexpr double kTcApply = 4.0;              // 1/s
constexpr double kMaxShiftClock = 10.0;       // s: the shift clock stops here

double Sgn(double v) { return static_cast<double>((v > 0.0) - (v < 0.0)); }

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

// The integral action of ABS and traction control on a factor in [0, 1]: with the slip's excess
// over its target (> 0: too much slip, in units of the target; >= -1), the factor falls at
// `release` per unit of excess and rises at `apply` per unit missing.
double SlipIntegralAction(double factor, double excess, double release, double apply, double h) {
  return std::clamp(factor + h * (excess > 0.0 ? -release * excess : -apply * excess), 0.0, 1.0);
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

}  // namespace

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
    ds.tc = SlipIntegralAction(ds.tc, std::max(excess, -1.0), kTcRelease, kTcApply, h);
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
      ds.abs[w] = SlipIntegralAction(ds.abs[w], excess, kAbsRelease, kAbsApply, h);
    } else {
      ds.abs[w] = 1.0;
    }
    u.wheel_brake_torque[w] =
        ds.abs[w] * brake * d.brake_torque[w] + in.handbrake * d.handbrake_torque[w];
    u.abs_factor[w] = ds.abs[w];
  }
  u.tc_factor = ds.tc;
  u.throttle = accelerator;
  u.brake = brake;

  // Road-wheel angles at the step start, for the record.
  const FrontWheelAngles geom = SteeringGeometry(p, x[sx::kHandWheel]);
  for (int w = 0; w < kNumWheels; ++w) {
    u.wheel_cos_gamma[w] = IsFront(w) ? geom.cos_gamma[w] : 1.0;
    u.wheel_sin_gamma[w] = IsFront(w) ? geom.sin_gamma[w] : 0.0;
    u.wheel_gamma[w] = std::atan2(u.wheel_sin_gamma[w], u.wheel_cos_gamma[w]);
    u.wheel_drive[w] = 0.0;
    u.wheel_brake[w] = u.wheel_brake_torque[w] / p.wheel[w].radius;
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
