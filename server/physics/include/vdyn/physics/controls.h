// Driver input and the controls the model applies during one step.
#pragma once

#include <array>

#include "vdyn/physics/params.h"
#include "vdyn/physics/state.h"

namespace vdyn {

// What a driver (keyboard, wheel, maneuver file, network) asks for. Latched at a step boundary.
struct DriverInput {
  double steer = 0;            // front road-wheel angle gamma, rad, positive to the left
  double throttle = 0;         // [-1, 1]; negative drives backwards (reverse gear)
  double brake = 0;            // [0, 1]
  bool cruise_on = false;      // automatic speed control engaged
  double cruise_speed = 0;     // set speed, m/s (>= 0)
};

// The controls held constant over one step, after saturation and the speed control.
struct AppliedControl {
  double gamma = 0;     // front road-wheel angle after the steering lock, rad
  double throttle = 0;  // effective [-1, 1]
  double brake = 0;     // effective [0, 1]
  double cruise_u = 0;  // speed-control output in [-1, 1] (0 when off)
  bool cruise_active = false;
  // Per wheel: steering angle gamma_W, commanded drive force Fh and brake force Fb (N).
  std::array<double, kNumWheels> gamma_W{};
  std::array<double, kNumWheels> cos_gamma_W{};  // held over the step: computed once
  std::array<double, kNumWheels> sin_gamma_W{};
  std::array<double, kNumWheels> drive_W{};
  std::array<double, kNumWheels> brake_W{};
};

// Clamps a driver input to its valid ranges; non-finite values become 0 (and are reported by
// the caller). Returns true when nothing had to change.
bool SanitizeInput(DriverInput& in);

// Stage "controls" of a step: saturation, the PI speed control with anti-windup (updating
// state.cruise_integral), and the split of drive and brake over the wheels.
AppliedControl ComputeControls(const Params& p, const DriverInput& in, double h, State& state);

}  // namespace vdyn
