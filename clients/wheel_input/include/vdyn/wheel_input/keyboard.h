// Driving with the keyboard: keys held (tracked from key events, so synthetic SDL events and real X
// events drive it alike) become rate-limited steering and pedal ramps. Steering returns to the
// centre when released; its travel shrinks with speed so a held key asks for at most a set lateral
// acceleration (a keyboard has no feel for the road).
//
//   Up / W     throttle            Down / S   brake           Left / A, Right / D  steer
//   Space      handbrake           C          cruise on/off   PageUp / =, PageDown / -  cruise set
//   speed Q / E      paddles (gear down / up)       Backspace  reset the vehicle V          camera
//   H          horn            Esc  emergency stop (F2 re-arms)
#pragma once

#include <cstdint>

#include <SDL2/SDL_scancode.h>

#include "vdyn/wheel_input/controls.h"
#include "vdyn/wheel_input/wheel_reader.h"

namespace vdyn::wheel_input {

struct KeyboardParams {
  double steer_rate = 1.5;         // fraction of the steering travel per second, key held
  double steer_return_rate = 3.0;  // back to the centre, key released
  double throttle_rise = 2.0;      // per second
  double throttle_fall = 4.0;
  double brake_rise = 3.0;
  double brake_fall = 6.0;
  double lateral_accel = 7.0;  // m/s^2 the full held steering asks for at speed
};

class KeyboardDriver {
 public:
  explicit KeyboardDriver(KeyboardParams params = {}) : params_(params) {}

  // A key went down or up (SDL_KEYDOWN / SDL_KEYUP; repeats ignored).
  void OnKey(SDL_Scancode key, bool down);
  // The window lost the keyboard: every key counts as released.
  void ReleaseAll();
  // Advances the ramps by dt and returns the controls: the hand-wheel angle is the steering
  // fraction of the vehicle's lock, turned back into a hand-wheel angle (lock * ratio).
  WheelControls Step(double dt_s, const VehicleInfo& v);

  double steer_fraction() const { return steer_; }  // [-1, 1] of the lock, positive left
  bool held(SDL_Scancode key) const;
  // Held now, or pressed since the last Step.
  bool pressed(SDL_Scancode key) const;
  // True once per press of the e-stop key / the re-arm key.
  bool TakeEstopPress();
  bool TakeRearmPress();

 private:
  KeyboardParams params_;
  // Whether a key is down, and whether it went down since the last Step (a tap shorter than the
  // loop's event period still presses a button once).
  std::uint8_t down_[SDL_NUM_SCANCODES] = {};
  std::uint8_t tapped_[SDL_NUM_SCANCODES] = {};
  double steer_ = 0, throttle_ = 0, brake_ = 0;
  bool estop_press_ = false, rearm_press_ = false;
};

}  // namespace vdyn::wheel_input
