// Closed-loop drivers: input computed from the vehicle's state, for endurance and stability runs.
#pragma once

#include <Eigen/Core>

#include "vdyn/physics/controls.h"
#include "vdyn/physics/state.h"

namespace vdyn {

// Drives circles of `radius` around `center` (counter-clockwise), aiming 30 degrees ahead on the
// circle, at `speed` on the speed control; every `step_period` s a 1 s step steer of
// +-`step_steer` rad (alternating) is added, and every `brake_period` s the last `brake_time` s
// are full braking with the speed control off.
struct CircuitDriver {
  Eigen::Vector2d center = Eigen::Vector2d::Zero();
  double radius = 30.0;        // m
  double speed = 30.0 / 3.6;   // m/s
  double step_period = 7.0;    // s
  double step_steer = 0.1745;  // rad (10 degrees)
  double brake_period = 40.0;  // s
  double brake_time = 4.0;     // s

  DriverInput Input(const State& state, double t) const;
};

}  // namespace vdyn
