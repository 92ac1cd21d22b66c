#include "vdyn/wheel_input/controls.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>
#include <utility>

#include "vdyn/base/gearbox.h"
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
  if (info.model == pb::VEHICLE_MODEL_FULL) {
    info.gear_count = static_cast<int>(p.gear_count());
    info.gear_ratio_first = p.gear_ratio_first();
    info.gear_ratio_top = p.gear_ratio_top();
    info.final_drive_ratio = p.final_drive_ratio();
    info.engine_rpm_limit = p.engine_rpm_limit();
    info.wheel_radius_m = p.lr().has_radius() ? p.lr().radius() : p.lf().radius();
  } else {
    info.gear_count = 0;
  }
}

namespace {
std::string GearName(int gear) {
  if (gear < 0) return "reverse";
  if (gear == 0) return "automatic";
  static const char* const kSuffix[] = {"th", "st", "nd", "rd"};
  const int last = gear % 10;
  const bool teen = gear % 100 >= 11 && gear % 100 <= 13;
  return std::to_string(gear) + (teen || last > 3 ? "th" : kSuffix[last]);
}
}  // namespace

std::string InputBuilder::ShiftRefusal(int to, const VehicleInfo& v) const {
  if (!v.speed_known) return {};
  char buf[160];
  const double speed = v.speed_kmh;
  // Into reverse, or out of it, only at a standstill (the car would be driven against its motion).
  constexpr double kStandstillKmh = 2.0;
  if ((to < 0) != (gear_ < 0) && std::abs(speed) > kStandstillKmh) {
    std::snprintf(buf, sizeof buf, "%s while moving at %.0f km/h: stop first",
                  to < 0 ? "reverse" : "out of reverse", std::abs(speed));
    return buf;
  }
  // A forward gear that would turn the engine past its limit at this speed.
  if (to > 0 && v.gear_count > 0 && v.wheel_radius_m > 0 && v.engine_rpm_limit > 0) {
    const double ratio = base::ForwardGearRatio(v.gear_ratio_first, v.gear_ratio_top,
                                                v.gear_count, std::min(to, v.gear_count));
    const double rpm = std::abs(speed) / 3.6 / v.wheel_radius_m * ratio * v.final_drive_ratio *
                       60.0 / (2.0 * std::numbers::pi);
    if (rpm > v.engine_rpm_limit) {
      std::snprintf(buf, sizeof buf,
                    "%s at %.0f km/h: the engine at %.0f rpm, past its %.0f limit",
                    GearName(to).c_str(), std::abs(speed), rpm, v.engine_rpm_limit);
      return buf;
    }
  }
  return {};
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

  // A paddle press shifts unless the shift would over-rev the engine or reverse while moving
  // (issue 31: E from automatic took 1st at 87 km/h, 8,482 rpm; Q passed into reverse at speed).
  for (const auto& [bit, step] : {std::pair{pb::BUTTON_PADDLE_RIGHT, 1}, {pb::BUTTON_PADDLE_LEFT, -1}}) {
    if ((pressed & static_cast<std::uint32_t>(bit)) == 0) continue;
    // The car's own gear count where its parameters are known (a 3-speed car counted to 5).
    const int top = v.gear_count > 0 ? v.gear_count : params_.forward_gears;
    const int to = std::clamp(gear_ + step, -1, top);
    if (to == gear_) continue;
    if (std::string why = ShiftRefusal(to, v); !why.empty()) {
      shift_refusal_ = std::move(why);
      shift_refused_at_ = now;
      ++shifts_refused_;
      continue;
    }
    gear_ = to;
    if (gear_ < 0) cruise_on_ = false;  // no cruise control backwards
  }

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

  if (pressed & pb::BUTTON_RESET) {
    // The vehicle starts again at rest: in the starting gear mode (automatic), cruise off.
    reset_request_ = true;
    gear_ = 0;
    cruise_on_ = false;
  }

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
