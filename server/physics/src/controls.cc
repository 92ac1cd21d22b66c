#include "vdyn/physics/controls.h"

#include <algorithm>
#include <cmath>

#include "vdyn/base/limits.h"
#include "vdyn/physics/full_model.h"

namespace vdyn {

bool SanitizeInput(DriverInput& in) {
  bool clean = true;
  auto fix = [&clean](double& v, double lo, double hi) {
    if (!std::isfinite(v)) {
      v = 0.0;
      clean = false;
    } else if (v < lo || v > hi) {
      v = std::clamp(v, lo, hi);
      clean = false;
    }
  };
  const limits::Range& steer =
      in.steer_mode == SteerMode::kHandWheel ? limits::kHandWheel : limits::kSteer;
  fix(in.steer, steer.lo, steer.hi);
  fix(in.throttle, limits::kThrottle.lo, limits::kThrottle.hi);
  fix(in.brake, limits::kBrake.lo, limits::kBrake.hi);
  fix(in.cruise_speed, limits::kCruiseSetKmh.lo / 3.6, limits::kCruiseSetKmh.hi / 3.6);
  fix(in.clutch, limits::kClutch.lo, limits::kClutch.hi);
  fix(in.handbrake, limits::kHandbrake.lo, limits::kHandbrake.hi);
  const int gear = std::clamp(in.gear, static_cast<int>(limits::kGear.lo),
                              static_cast<int>(limits::kGear.hi));
  if (gear != in.gear) {
    in.gear = gear;
    clean = false;
  }
  return clean;
}

void CruiseControl(const Params& p, const DriverInput& in, double h, State& state,
                   AppliedControl& u) {
  // Automatic speed control: PI on the longitudinal speed vx (body X), output in [-1, 1]:
  // positive drives, negative brakes. Conditional integration is the anti-windup: the integral
  // only moves when the output is not saturated in the direction the error pushes. Pressing the
  // brake pedal overrides the control and clears its integral.
  if (in.cruise_on && in.brake <= 0.0) {
    const Eigen::Matrix3d R_WB = Orientation(state.x).normalized().toRotationMatrix();
    const double vx = (R_WB.transpose() * Velocity(state.x)).x();
    const double e = in.cruise_speed - vx;
    const double unsat = p.cruise_kp * e + state.cruise_integral;
    const bool wind_up = (unsat >= 1.0 && e > 0.0) || (unsat <= -1.0 && e < 0.0);
    // A driver pressing the throttle beyond the control's output overrides it: hold the integral.
    const bool overridden = in.throttle > 0.0 && in.throttle > std::clamp(unsat, -1.0, 1.0);
    if (!wind_up && !overridden) {
      state.cruise_integral = std::clamp(state.cruise_integral + p.cruise_ki * e * h, -1.0, 1.0);
    }
    u.cruise_u = std::clamp(p.cruise_kp * e + state.cruise_integral, -1.0, 1.0);
    u.cruise_active = true;
    if (u.throttle >= 0.0) u.throttle = std::max(u.throttle, u.cruise_u);
    u.brake = std::max(u.brake, -u.cruise_u);
  } else {
    state.cruise_integral = 0.0;
  }
}

AppliedControl ComputeControls(const Params& p, const DriverInput& in, double h, State& state) {
  if (p.model == VehicleModel::kFull) return ComputeControlsFull(p, in, h, state);
  AppliedControl u;
  // The paper's model steers the road wheels directly: a hand-wheel angle is divided by the
  // steering ratio, and hands off the wheel steer straight ahead.
  double steer = in.steer;
  if (in.steer_mode == SteerMode::kHandWheel) steer = in.steer / p.steering_ratio;
  if (in.steer_mode == SteerMode::kHandsOff) steer = 0.0;
  u.gamma = std::clamp(steer, -p.steering_lock, p.steering_lock);
  u.throttle = in.throttle;
  u.brake = in.brake;
  CruiseControl(p, in, h, state, u);

  const double drive = u.throttle * p.drive_force_max;
  const double brake = u.brake * p.brake_force_max;
  for (int w = 0; w < kNumWheels; ++w) {
    const bool front = IsFront(w);
    u.wheel_gamma[w] = front ? u.gamma : 0.0;  // parallel front steering, rear wheels fixed
    u.wheel_cos_gamma[w] = std::cos(u.wheel_gamma[w]);
    u.wheel_sin_gamma[w] = std::sin(u.wheel_gamma[w]);
    u.wheel_drive[w] =
        0.5 * drive * (front ? p.drive_front_fraction : 1.0 - p.drive_front_fraction);
    u.wheel_brake[w] =
        0.5 * brake * (front ? p.brake_front_fraction : 1.0 - p.brake_front_fraction);
  }
  return u;
}

}  // namespace vdyn
