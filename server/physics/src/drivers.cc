#include "vdyn/physics/drivers.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace vdyn {

DriverInput CircuitDriver::Input(const State& state, double t) const {
  const Eigen::Vector3d p = Position(state.x);
  const double ang = std::atan2(p.y() - center.y(), p.x() - center.x()) + std::numbers::pi / 6.0;
  const Eigen::Vector2d target = center + radius * Eigen::Vector2d(std::cos(ang), std::sin(ang));
  const double yaw = RollPitchYaw(Orientation(state.x)).z();
  const double err = std::remainder(std::atan2(target.y() - p.y(), target.x() - p.x()) - yaw,
                                    2.0 * std::numbers::pi);
  DriverInput in;
  in.steer = std::clamp(1.5 * err, -0.5, 0.5);
  if (std::fmod(t, step_period) < 1.0) {
    in.steer += std::fmod(t, 2.0 * step_period) < step_period ? step_steer : -step_steer;
  }
  if (std::fmod(t, brake_period) > brake_period - brake_time) {
    in.brake = 1.0;
  } else {
    in.cruise_on = true;
    in.cruise_speed = speed;
  }
  return in;
}

}  // namespace vdyn
