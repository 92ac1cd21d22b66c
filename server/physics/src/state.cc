#include "vdyn/physics/state.h"

#include <algorithm>
#include <cmath>

#include "vdyn/base/hash.h"

namespace vdyn {

Eigen::Vector3d RollPitchYaw(const Eigen::Quaterniond& q_WB) {
  const Eigen::Matrix3d R = q_WB.normalized().toRotationMatrix();
  // R = Rz(yaw) * Ry(pitch) * Rx(roll)
  const double pitch = std::asin(std::clamp(-R(2, 0), -1.0, 1.0));
  const double roll = std::atan2(R(2, 1), R(2, 2));
  const double yaw = std::atan2(R(1, 0), R(0, 0));
  return {roll, pitch, yaw};
}

Eigen::Quaterniond QuaternionFromRollPitchYaw(double roll, double pitch, double yaw) {
  return Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                            Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                            Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()));
}

std::uint64_t StateHash(const State& s) {
  // vdyn-hash64 (docs/hash.md): the integrated numbers of x, the speed control's integral, the
  // full model's discrete state, the step.
  base::WordHash h;
  const int n = IntegratedSize(s.model);
  for (int i = 0; i < n; ++i) h.Double(s.x[i]);
  h.Double(s.cruise_integral);
  if (s.model == VehicleModel::kFull) {
    h.Int(s.discrete.gear);
    h.Double(s.discrete.shift_time);
    for (double a : s.discrete.abs) h.Double(a);
    h.Double(s.discrete.tc);
  }
  h.Int(s.step);
  return h.Final();
}

}  // namespace vdyn
