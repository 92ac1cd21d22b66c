#include "vdyn/wheel_input/keyboard.h"

#include <algorithm>
#include <cmath>

#include "vdyn/input.pb.h"

namespace vdyn::wheel_input {
namespace {

// Moves `x` towards `target` by at most rate * dt.
double Ramp(double x, double target, double rate, double dt) {
  const double step = rate * dt;
  if (x < target) return std::min(x + step, target);
  return std::max(x - step, target);
}

}  // namespace

void KeyboardDriver::OnKey(SDL_Scancode key, bool down) {
  if (key < 0 || key >= SDL_NUM_SCANCODES) return;
  const bool was = down_[key] != 0;
  down_[key] = down ? 1 : 0;
  if (down && !was) {
    tapped_[key] = 1;
    if (key == SDL_SCANCODE_ESCAPE) estop_press_ = true;
    if (key == SDL_SCANCODE_F2) rearm_press_ = true;
  }
}

void KeyboardDriver::ReleaseAll() {
  for (auto& d : down_) d = 0;
  for (auto& t : tapped_) t = 0;
}

bool KeyboardDriver::held(SDL_Scancode key) const {
  return key >= 0 && key < SDL_NUM_SCANCODES && down_[key] != 0;
}

bool KeyboardDriver::pressed(SDL_Scancode key) const {
  return held(key) || (key >= 0 && key < SDL_NUM_SCANCODES && tapped_[key] != 0);
}

bool KeyboardDriver::TakeEstopPress() {
  const bool p = estop_press_;
  estop_press_ = false;
  return p;
}

bool KeyboardDriver::TakeRearmPress() {
  const bool p = rearm_press_;
  rearm_press_ = false;
  return p;
}

WheelControls KeyboardDriver::Step(double dt_s, const VehicleInfo& v) {
  const double dt = std::clamp(dt_s, 0.0, 0.1);
  const bool left = held(SDL_SCANCODE_LEFT) || held(SDL_SCANCODE_A);
  const bool right = held(SDL_SCANCODE_RIGHT) || held(SDL_SCANCODE_D);
  const bool gas = held(SDL_SCANCODE_UP) || held(SDL_SCANCODE_W);
  const bool brake = held(SDL_SCANCODE_DOWN) || held(SDL_SCANCODE_S);

  // The steering a held key asks for: the whole lock when slow; at speed v, the road-wheel angle
  // whose steady turn has the lateral acceleration a (kinematic: a = v^2 * gamma / L).
  double limit = 1.0;
  if (v.speed_known) {
    const double speed = std::abs(v.speed_kmh) / 3.6;
    if (speed > 0.1 && v.steering_lock > 0) {
      limit = std::clamp(params_.lateral_accel * v.wheelbase_m / (speed * speed) / v.steering_lock,
                         0.05, 1.0);
    }
  }
  const double target = left == right ? 0.0 : (left ? limit : -limit);
  const bool returning = target == 0.0 || (target > 0) != (steer_ > 0);
  steer_ = Ramp(steer_, target, returning ? params_.steer_return_rate : params_.steer_rate, dt);
  throttle_ =
      Ramp(throttle_, gas ? 1.0 : 0.0, gas ? params_.throttle_rise : params_.throttle_fall, dt);
  brake_ = Ramp(brake_, brake ? 1.0 : 0.0, brake ? params_.brake_rise : params_.brake_fall, dt);

  WheelControls c;
  c.hand_angle_rad = steer_ * v.steering_lock * v.steering_ratio;
  c.road_wheel_only = true;
  c.throttle = throttle_;
  c.brake = brake_;
  c.handbrake = held(SDL_SCANCODE_SPACE) ? 1.0 : 0.0;
  std::uint32_t b = 0;
  if (pressed(SDL_SCANCODE_Q)) b |= pb::BUTTON_PADDLE_LEFT;
  if (pressed(SDL_SCANCODE_E)) b |= pb::BUTTON_PADDLE_RIGHT;
  if (pressed(SDL_SCANCODE_C)) b |= pb::BUTTON_CRUISE_TOGGLE;
  if (pressed(SDL_SCANCODE_PAGEUP) || pressed(SDL_SCANCODE_EQUALS) ||
      pressed(SDL_SCANCODE_KP_PLUS)) {
    b |= pb::BUTTON_CRUISE_UP;
  }
  if (pressed(SDL_SCANCODE_PAGEDOWN) || pressed(SDL_SCANCODE_MINUS) ||
      pressed(SDL_SCANCODE_KP_MINUS)) {
    b |= pb::BUTTON_CRUISE_DOWN;
  }
  if (pressed(SDL_SCANCODE_BACKSPACE)) b |= pb::BUTTON_RESET;
  if (pressed(SDL_SCANCODE_V)) b |= pb::BUTTON_CAMERA;
  if (pressed(SDL_SCANCODE_H)) b |= pb::BUTTON_HORN;
  c.buttons = b;
  for (auto& t : tapped_) t = 0;
  return c;
}

}  // namespace vdyn::wheel_input
