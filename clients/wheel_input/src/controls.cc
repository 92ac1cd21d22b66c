#include "vdyn/wheel_input/controls.h"

#include <algorithm>
#include <cmath>

#include "vdyn/base/limits.h"
#include "vdyn/client/driver_input.h"

namespace vdyn::wheel_input {

void ApplyParams(const pb::VehicleParams& p, VehicleInfo& info) {
  info.params_known = true;
  info.model = p.has_model() && p.model() == pb::VEHICLE_MODEL_FULL ? pb::VEHICLE_MODEL_FULL
                                                                    : pb::VEHICLE_MODEL_PAPER;
  if (p.has_steering_ratio() && p.steering_ratio() > 0) info.steering_ratio = p.steering_ratio();
  if (p.has_steering_lock() && p.steering_lock() > 0) info.steering_lock = p.steering_lock();
  if (p.has_b() && p.has_c() && p.b() + p.c() > 0) info.wheelbase_m = p.b() + p.c();
}

SteerCommand ToSteer(double hand_angle_rad, const VehicleInfo& v, bool road_wheel_only) {
  SteerCommand s;
  if (v.model == pb::VEHICLE_MODEL_FULL && !road_wheel_only) {
    s.mode = pb::STEER_HAND_WHEEL;
    s.steer = limits::Clamp(limits::kHandWheel, hand_angle_rad);
  } else {
    s.mode = pb::STEER_ROAD_WHEEL;
    const double lock = std::min(v.steering_lock, limits::kSteer.hi);
    s.steer = std::clamp(hand_angle_rad / v.steering_ratio, -lock, lock);
    if (!std::isfinite(s.steer)) s.steer = 0.0;
  }
  return s;
}

bool InputBuilder::TakeResetRequest() {
  const bool r = reset_request_;
  reset_request_ = false;
  return r;
}

void InputBuilder::Build(base::MonoTime now, const WheelControls& c, const VehicleInfo& v,
                         pb::DriverInput& out) {
  const std::uint32_t pressed = c.buttons & ~previous_buttons_;
  const std::uint32_t released = previous_buttons_ & ~c.buttons;
  previous_buttons_ = c.buttons;

  if (pressed & pb::BUTTON_PADDLE_RIGHT) gear_ = std::min(gear_ + 1, params_.forward_gears);
  if (pressed & pb::BUTTON_PADDLE_LEFT) gear_ = std::max(gear_ - 1, -1);

  if (pressed & pb::BUTTON_CRUISE_TOGGLE) {
    if (cruise_on_) {
      cruise_on_ = false;
    } else if (v.speed_known) {
      cruise_on_ = true;
      cruise_set_kmh_ =
          limits::Clamp(limits::kCruiseSetKmh, std::round(std::max(v.speed_kmh, 0.0)));
    } else {
      ++cruise_ignored_;
    }
  }
  if (pressed & pb::BUTTON_CRUISE_UP) {
    // "Resume / +": switches a set cruise control on, or raises the set speed.
    if (cruise_on_) {
      cruise_set_kmh_ =
          limits::Clamp(limits::kCruiseSetKmh, cruise_set_kmh_ + params_.cruise_step_kmh);
    } else if (cruise_set_kmh_ > 0) {
      cruise_on_ = true;
    }
  }
  if ((pressed & pb::BUTTON_CRUISE_DOWN) && cruise_on_) {
    cruise_set_kmh_ =
        limits::Clamp(limits::kCruiseSetKmh, cruise_set_kmh_ - params_.cruise_step_kmh);
  }
  if (c.brake > params_.cruise_cancel_brake) cruise_on_ = false;

  if (pressed & pb::BUTTON_RESET) reset_request_ = true;

  // The e-stop button latches at once; holding it for estop_rearm_hold while latched re-arms.
  if (pressed & pb::BUTTON_ESTOP) {
    estop_press_started_latched_ = estop_;
    estop_pressed_at_ = now;
    estop_ = true;
  }
  if ((c.buttons & pb::BUTTON_ESTOP) && estop_press_started_latched_ &&
      now - estop_pressed_at_ >= params_.estop_rearm_hold) {
    estop_ = false;
    estop_press_started_latched_ = false;
  }
  if (released & pb::BUTTON_ESTOP) estop_press_started_latched_ = false;

  last_hand_angle_ = c.hand_angle_rad;
  last_road_wheel_only_ = c.road_wheel_only;
  const SteerCommand s = ToSteer(c.hand_angle_rad, v, c.road_wheel_only);
  out.set_steer_mode(s.mode);
  out.set_steer(s.steer);
  out.set_throttle(c.throttle);
  out.set_brake(c.brake);
  out.set_clutch(c.clutch);
  out.set_handbrake(c.handbrake);
  out.set_gear(gear_);
  out.set_cruise_on(cruise_on_);
  out.set_cruise_set_kmh(cruise_set_kmh_);
  out.set_buttons((c.buttons & ~static_cast<std::uint32_t>(pb::BUTTON_ESTOP)) |
                  (estop_ ? static_cast<std::uint32_t>(pb::BUTTON_ESTOP) : 0u));
  clamped_ += static_cast<std::uint64_t>(client::ClampToLimits(out));
}

void InputBuilder::Neutral(double brake, const VehicleInfo& v, pb::DriverInput& out) {
  previous_buttons_ = 0;
  cruise_on_ = false;
  const SteerCommand s = ToSteer(last_hand_angle_, v, last_road_wheel_only_);
  out.set_steer_mode(s.mode);
  out.set_steer(s.steer);
  out.set_throttle(0.0);
  out.set_brake(brake);
  out.set_clutch(0.0);
  out.set_handbrake(0.0);
  out.set_gear(gear_);
  out.set_cruise_on(false);
  out.set_cruise_set_kmh(cruise_set_kmh_);
  out.set_buttons(estop_ ? static_cast<std::uint32_t>(pb::BUTTON_ESTOP) : 0u);
  clamped_ += static_cast<std::uint64_t>(client::ClampToLimits(out));
}

}  // namespace vdyn::wheel_input
