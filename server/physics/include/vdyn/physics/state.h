// State: exactly what is integrated, recorded and hashed; nothing derived lives here.
#pragma once

#include <cstdint>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace vdyn {

// The continuous state x integrated by RK4 (13 numbers):
//   x[0..2]   p_WT_W  position of the centre of gravity T in the world frame W, m
//   x[3..6]   q_WB    orientation of body B in W, unit quaternion (w, x, y, z)
//   x[7..9]   v_WT_W  velocity of T in W, expressed in W, m/s
//   x[10..12] w_WB_B  angular velocity of B in W, expressed in B, rad/s
using StateVector = Eigen::Matrix<double, 13, 1>;

namespace sx {
inline constexpr int kP = 0;
inline constexpr int kQ = 3;
inline constexpr int kV = 7;
inline constexpr int kW = 10;
}  // namespace sx

struct State {
  // At the world origin, level, at rest (identity orientation).
  StateVector x = (StateVector() << 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0).finished();
  // Discrete state of the automatic speed control (integral of the speed error, scaled by ki).
  double cruise_integral = 0;
  // Steps taken since the start; simulation time t = step * h exactly.
  std::int64_t step = 0;
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

// The state hash: vdyn-hash64 (vdyn/base/hash.h, docs/hash.md) over the bits of x[0..12], the
// cruise integral and the step, in that order. Two runs agree on it exactly when they agree bit
// for bit.
std::uint64_t StateHash(const State& s);

}  // namespace vdyn
