// State: exactly what is integrated, recorded and hashed; nothing derived lives here.
#pragma once

#include <array>
#include <cstdint>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace vdyn {

// Which equations of motion a vehicle follows (VehicleParams.model). The state's layout depends
// on it: the paper's model integrates the first 13 numbers of x, the full model all 37.
enum class VehicleModel { kPaper, kFull };

// The continuous state x integrated by RK4:
//   x[0..2]   p_WT_W  position of the centre of gravity T in the world frame W, m
//   x[3..6]   q_WB    orientation of body B in W, unit quaternion (w, x, y, z)
//   x[7..9]   v_WT_W  velocity of T in W, expressed in W, m/s
//   x[10..12] w_WB_B  angular velocity of B in W, expressed in B, rad/s
// The full model adds, per wheel LF, RF, LR, RR (docs/model.md, "The full model"):
//   x[13..16] omega   wheel spin rate about its axle, rad/s (positive rolling forward)
//   x[17..20] u       longitudinal deflection of the tire's contact patch, m
//   x[21..24] v       lateral deflection of the contact patch, m
//   x[25..28] s_b     brake friction state (LuGre, normalised: |s_b| <= 1), 1
//   x[29..32] l_s     spring length (the wheel's travel along -Z_B below A), m
// and for the vehicle:
//   x[33]     omega_e engine speed, rad/s
//   x[34]     s_c     clutch friction state (LuGre, normalised), 1
//   x[35]     delta_h hand-wheel angle, rad, positive to the left
//   x[36]     omega_h hand-wheel rate, rad/s
// The paper's model leaves x[13..36] at zero; they are neither integrated nor hashed for it.
inline constexpr int kStateSize = 37;
inline constexpr int kPaperStateSize = 13;
using StateVector = Eigen::Matrix<double, kStateSize, 1>;

namespace sx {
inline constexpr int kP = 0;
inline constexpr int kQ = 3;
inline constexpr int kV = 7;
inline constexpr int kW = 10;
// Full model (first index of each group of four wheels, then single numbers).
inline constexpr int kWheelSpin = 13;
inline constexpr int kDeflectionLong = 17;
inline constexpr int kDeflectionLat = 21;
inline constexpr int kBrake = 25;
inline constexpr int kSpring = 29;
inline constexpr int kEngine = 33;
inline constexpr int kClutch = 34;
inline constexpr int kHandWheel = 35;
inline constexpr int kHandWheelRate = 36;
}  // namespace sx

// Number of integrated (and hashed) numbers of x for a model.
constexpr int IntegratedSize(VehicleModel m) {
  return m == VehicleModel::kFull ? kStateSize : kPaperStateSize;
}

// Discrete state of the full model's controllers, updated once per step at its start.
struct DiscreteState {
  std::int32_t gear = 0;          // engaged gear: -1 reverse, 0 neutral, 1..N
  double shift_time = 0;          // s since the last gear change began (saturates at 10 s)
  std::array<double, 4> abs{1.0, 1.0, 1.0, 1.0};  // ABS brake-pressure factor per wheel, [0, 1]
  double tc = 1.0;                // traction control's engine-torque factor, [0, 1]
};

struct State {
  // At the world origin, level, at rest (identity orientation).
  StateVector x = []() {
    StateVector v = StateVector::Zero();
    v[sx::kQ] = 1.0;
    return v;
  }();
  // Discrete state of the automatic speed control (integral of the speed error, scaled by ki).
  double cruise_integral = 0;
  // Steps taken since the start; simulation time t = step * h exactly.
  std::int64_t step = 0;
  // Which model's layout x follows, and that model's discrete state (full model only).
  VehicleModel model = VehicleModel::kPaper;
  DiscreteState discrete;
};

inline Eigen::Vector3d Position(const StateVector& x) { return x.segment<3>(sx::kP); }
inline Eigen::Quaterniond Orientation(const StateVector& x) {
  return Eigen::Quaterniond(x[sx::kQ], x[sx::kQ + 1], x[sx::kQ + 2], x[sx::kQ + 3]);
}
inline Eigen::Vector3d Velocity(const StateVector& x) { return x.segment<3>(sx::kV); }
inline Eigen::Vector3d AngularVelocityB(const StateVector& x) { return x.segment<3>(sx::kW); }

inline void SetPosition(StateVector& x, const Eigen::Vector3d& p) { x.segment<3>(sx::kP) = p; }
inline void SetOrientation(StateVector& x, const Eigen::Quaterniond& q) {
  x[sx::kQ] = q.w();
  x[sx::kQ + 1] = q.x();
  x[sx::kQ + 2] = q.y();
  x[sx::kQ + 3] = q.z();
}
inline void SetVelocity(StateVector& x, const Eigen::Vector3d& v) { x.segment<3>(sx::kV) = v; }
inline void SetAngularVelocityB(StateVector& x, const Eigen::Vector3d& w) {
  x.segment<3>(sx::kW) = w;
}

// Roll, pitch, yaw (Z-Y-X intrinsic: yaw about Z_W, then pitch, then roll), rad.
// ISO 8855 signs: roll positive right side down, pitch positive nose down, yaw positive to the left.
Eigen::Vector3d RollPitchYaw(const Eigen::Quaterniond& q_WB);
Eigen::Quaterniond QuaternionFromRollPitchYaw(double roll, double pitch, double yaw);

// The state hash: vdyn-hash64 (vdyn/base/hash.h, docs/hash.md). Paper model: the bits of
// x[0..12], the cruise integral and the step, in that order (unchanged since the paper model
// was the only one). Full model: x[0..36], the cruise integral, the gear, the shift time, the
// four ABS factors, the traction-control factor, then the step. Two runs agree on it exactly
// when they agree bit for bit.
std::uint64_t StateHash(const State& s);

}  // namespace vdyn
