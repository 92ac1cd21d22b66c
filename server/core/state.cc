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
// FNV-1a over 64-bit words (not bytes): a word at a time, then a final avalanche (the mixer of
// MurmurHash3's fmix64) so every input bit reaches every output bit.
void Mix(std::uint64_t& h, std::uint64_t word) {
  h ^= word;
  h *= 1099511628211ull;
}
std::uint64_t Bits(double v) {
  std::uint64_t u;
  std::memcpy(&u, &v, sizeof u);
  return u;
}
}  // namespace

std::uint64_t StateHash(const State& s) {
  std::uint64_t h = 14695981039346656037ull;
  for (int i = 0; i < s.x.size(); ++i) Mix(h, Bits(s.x[i]));
  Mix(h, Bits(s.cruise_integral));
  Mix(h, static_cast<std::uint64_t>(s.step));
  h ^= h >> 33;
  h *= 0xff51afd7ed558ccdull;
  h ^= h >> 33;
  h *= 0xc4ceb9fe1a85ec53ull;
  h ^= h >> 33;
  return h;
}

}  // namespace vdyn
