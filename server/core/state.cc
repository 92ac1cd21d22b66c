#include "state.h"

#include <cmath>
#include <cstring>

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

namespace {
void Fnv(std::uint64_t& h, const void* data, std::size_t n) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < n; ++i) {
    h ^= p[i];
    h *= 1099511628211ull;
  }
}
}  // namespace

std::uint64_t StateHash(const State& s) {
  std::uint64_t h = 14695981039346656037ull;
  Fnv(h, s.x.data(), sizeof(double) * static_cast<std::size_t>(s.x.size()));
  Fnv(h, &s.cruise_integral, sizeof s.cruise_integral);
  Fnv(h, &s.step, sizeof s.step);
  return h;
}

}  // namespace vdyn
