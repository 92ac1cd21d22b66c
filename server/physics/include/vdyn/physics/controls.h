// Driver input and the controls the model applies during one step.
#pragma once

#include <array>

#include "vdyn/physics/params.h"
#include "vdyn/physics/state.h"

namespace vdyn {

// How DriverInput::steer is meant (vdyn.pb.SteerMode).
enum class SteerMode { kRoadWheel = 0, kHandWheel = 1, kHandsOff = 2 };

// What a driver (keyboard, wheel, maneuver file, network) asks for. Latched at a step boundary.
struct DriverInput {
  double steer = 0;            // rad, positive to the left: see steer_mode
  double throttle = 0;         // [-1, 1]; negative drives backwards (the full model: see below)
  double brake = 0;            // [0, 1]
  bool cruise_on = false;      // automatic speed control engaged
  double cruise_speed = 0;     // set speed, m/s (>= 0)
  // kRoadWheel: steer is the front road-wheel angle gamma. kHandWheel: the hand-wheel angle
  // (the paper's model divides it by the steering ratio). kHandsOff: steer is ignored; the full
  // model's column turns on its own, the paper's model steers straight ahead.
  SteerMode steer_mode = SteerMode::kRoadWheel;
  // Full model only (the paper's model has no clutch, handbrake or gearbox):
  double clutch = 0;     // [0, 1], 1 = pedal down (disengaged)
  double handbrake = 0;  // [0, 1]
  int gear = 0;          // 0 automatic; -1 reverse, 1..N a gear chosen by the driver
};

// The controls held constant over one step, after saturation and the speed control.
struct AppliedControl {
  double gamma = 0;     // front road-wheel angle after the steering lock, rad (paper model)
  double throttle = 0;  // effective [-1, 1]
  double brake = 0;     // effective [0, 1]
  double cruise_u = 0;  // speed-control output in [-1, 1] (0 when off)
  bool cruise_active = false;
  // Per wheel: steering angle wheel_gamma, commanded drive force Fh and brake force Fb (N).
  std::array<double, kNumWheels> wheel_gamma{};
  std::array<double, kNumWheels> wheel_cos_gamma{};  // held over the step: computed once
  std::array<double, kNumWheels> wheel_sin_gamma{};
  std::array<double, kNumWheels> wheel_drive{};
  std::array<double, kNumWheels> wheel_brake{};

  // --- The full model ---------------------------------------------------------------------------
  bool hands_on = true;          // the column follows hand_wheel_target (false: hands off)
  double hand_wheel_target = 0;  // commanded hand-wheel angle, rad (inside the steering lock)
  double pedal = 0;              // accelerator at the engine before governor and limiter, [0, 1]
  double clutch_engagement = 0;  // clutch pedal and shifting: capacity factor, [0, 1]
  int gear = 0;                  // engaged gear for the step (-1, 0 neutral, 1..N)
  double gearbox_ratio = 0;      // signed total ratio gear * final drive (0 in neutral)
  bool shifting = false;
  bool automatic = true;
  std::array<double, kNumWheels> wheel_brake_torque{};  // brake + handbrake capacity, N*m
  std::array<double, kNumWheels> abs_factor{};          // ABS brake-pressure factor applied
  double tc_factor = 0;                                 // traction control's torque factor applied
};

// Clamps a driver input to its valid ranges; non-finite values become 0 (and are reported by
// the caller). Returns true when nothing had to change.
bool SanitizeInput(DriverInput& in);

// The PI speed control with anti-windup (both models): updates state.cruise_integral and
// u.cruise_u, u.cruise_active, u.throttle and u.brake (which hold the driver's pedals on entry).
void CruiseControl(const Params& p, const DriverInput& in, double h, State& state,
                   AppliedControl& u);

// Stage "controls" of a step: saturation, the PI speed control with anti-windup (updating
// state.cruise_integral), and the split of drive and brake over the wheels. For the full model
// also the gearbox (automatic or the driver's gear), the shift timer, ABS and traction control,
// updating state.discrete.
AppliedControl ComputeControls(const Params& p, const DriverInput& in, double h, State& state);

}  // namespace vdyn
