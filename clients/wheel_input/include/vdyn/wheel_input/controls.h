// From what the driver does (a wheel's or the keyboard's controls) to the DriverInput a rig sends:
// the steering angle in the form the vehicle's model understands, the gear counted by the paddle
// shifters, cruise control from buttons, the emergency stop latch, and the button bits.
#pragma once

#include <cstdint>
#include <string>

#include "vdyn/base/time.h"
#include "vdyn/input.pb.h"
#include "vdyn/vehicle_params.pb.h"
#include "vdyn/wheel_input/wheel_reader.h"

namespace vdyn::wheel_input {

// What the rig knows of its vehicle (from the server's parameters and newest state).
struct VehicleInfo {
  bool params_known = false;
  pb::VehicleModel model = pb::VEHICLE_MODEL_PAPER;
  double steering_ratio = 15.0;  // hand wheel / road wheel
  double steering_lock = 0.6;    // rad, the largest road-wheel angle
  double wheelbase_m = 2.7;      // b + c
  bool speed_known = false;
  double speed_kmh = 0;  // along the body's X axis (negative backwards)
  // The full model's gearbox (zero: not known, or the paper's model, which has none).
  int gear_count = 0;
  double gear_ratio_first = 0, gear_ratio_top = 0, final_drive_ratio = 0;
  double engine_rpm_limit = 0;  // rpm
  double wheel_radius_m = 0;    // a rear wheel's
};
// The fields of VehicleInfo a parameter message gives (unset fields keep their defaults).
void ApplyParams(const pb::VehicleParams& p, VehicleInfo& info);

// The steer command for a hand-wheel angle: for the full model (which has a steering column) the
// hand-wheel angle itself; for the paper's model, or a source with no hand wheel (road_wheel_only:
// the keyboard), the road-wheel angle it turns, angle / ratio, clamped to the steering lock.
struct SteerCommand {
  pb::SteerMode mode = pb::STEER_ROAD_WHEEL;
  double steer = 0;  // rad
};
SteerCommand ToSteer(double hand_angle_rad, const VehicleInfo& v, bool road_wheel_only = false);

struct InputBuilderParams {
  int forward_gears = 6;              // the paddles count -1 (reverse), 0 (automatic), 1..N
  double cruise_step_kmh = 5.0;       // per press of cruise up / down
  double cruise_cancel_brake = 0.05;  // braking beyond this switches cruise off, as in a car
  base::Nanos estop_rearm_hold = base::Milliseconds(2000);  // hold the e-stop button to re-arm
};

// Keeps the state buttons change (gear, cruise, e-stop latch) and fills the message.
class InputBuilder {
 public:
  explicit InputBuilder(InputBuilderParams params = {}) : params_(params) {}

  // Fills `out` (the fields a rig owns; vehicle, source, sequence and stamp are the publisher's)
  // from the controls, acting on button edges since the last call.
  void Build(base::MonoTime now, const WheelControls& c, const VehicleInfo& v,
             pb::DriverInput& out);

  // A safe neutral while the device is gone: no throttle, `brake`, steering held where it was,
  // cruise off, no buttons (the e-stop latch stays).
  void Neutral(double brake, const VehicleInfo& v, pb::DriverInput& out);

  // The emergency stop from outside the wheel (a key): latch, or re-arm.
  void LatchEstop() { estop_ = true; }
  void RearmEstop() { estop_ = false; }
  bool estop() const { return estop_; }
  int gear() const { return gear_; }
  // The last gear shift refused, and why ("1st at 87 km/h: the engine at 10398 rpm, past its 6800
  // limit"; "reverse while moving at 45 km/h: stop first"); empty when none.
  const std::string& shift_refusal() const { return shift_refusal_; }
  base::MonoTime shift_refused_at() const { return shift_refused_at_; }
  std::uint64_t shifts_refused() const { return shifts_refused_; }
  bool cruise_on() const { return cruise_on_; }
  double cruise_set_kmh() const { return cruise_set_kmh_; }
  // True once per press of the reset button (the rig then asks the server for a reset).
  bool TakeResetRequest();
  // Fields ClampToLimits had to change, since the start.
  std::uint64_t clamped() const { return clamped_; }
  // Cruise presses ignored because the speed was not known yet.
  std::uint64_t cruise_ignored() const { return cruise_ignored_; }
  double last_hand_angle_rad() const { return last_hand_angle_; }

 private:
  InputBuilderParams params_;
  std::uint32_t previous_buttons_ = 0;
  // A paddle press's gear, or the reason it is refused (empty: allowed).
  std::string ShiftRefusal(int to, const VehicleInfo& v) const;

  int gear_ = 0;  // -1 reverse, 0 automatic (the starting mode, again after a reset), 1..N
  std::string shift_refusal_;
  base::MonoTime shift_refused_at_{};
  std::uint64_t shifts_refused_ = 0;
  bool cruise_on_ = false;
  double cruise_set_kmh_ = 0;
  bool estop_ = false;
  bool estop_press_started_latched_ = false;
  base::MonoTime estop_pressed_at_{};
  bool reset_request_ = false;
  double last_hand_angle_ = 0;
  bool last_road_wheel_only_ = false;
  std::uint64_t clamped_ = 0;
  std::uint64_t cruise_ignored_ = 0;
};

}  // namespace vdyn::wheel_input
