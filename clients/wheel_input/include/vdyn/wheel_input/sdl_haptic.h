// Force feedback through SDL's haptic layer: one CONSTANT effect on the steering axis (SDL picks
// the axis, SDL_HAPTIC_STEERING_AXIS), autocentre off, gain 100 %, and a DAMPER where the device
// has one. Every update carries a finite length and the effect is started again at least every
// half length, so on every driver (ff-memless restarts the length on an update, HID PID devices
// count it from the start) a client that stops updating goes quiet within one length.
#pragma once

#include <memory>
#include <string>

#include <SDL2/SDL_haptic.h>
#include <SDL2/SDL_joystick.h>

#include "vdyn/wheel_input/ffb.h"

namespace vdyn::wheel_input {

class SdlHaptic : public HapticDevice {
 public:
  // The joystick's haptic device, ready; nullptr and the reason when it has none, or no CONSTANT.
  static std::unique_ptr<SdlHaptic> Open(SDL_Joystick* joystick, std::string* why);
  ~SdlHaptic() override;
  SdlHaptic(const SdlHaptic&) = delete;
  SdlHaptic& operator=(const SdlHaptic&) = delete;

  bool SetConstant(double level, base::Nanos length) override;
  bool SetDamper(double coefficient, base::Nanos length) override;
  void Stop() override;
  bool has_damper() const override { return damper_id_ >= 0; }
  const std::string& last_error() const override { return error_; }
  // "constant, damper, autocentre off, gain"
  const std::string& features() const { return features_; }

 private:
  explicit SdlHaptic(SDL_Haptic* h) : haptic_(h) {}
  bool Play(int id, SDL_HapticEffect& effect, base::MonoTime& run_at, bool& running,
            base::Nanos length);

  SDL_Haptic* haptic_;
  int constant_id_ = -1;
  int damper_id_ = -1;
  SDL_HapticEffect constant_{};
  SDL_HapticEffect damper_{};
  base::MonoTime constant_run_at_{}, damper_run_at_{};
  bool constant_running_ = false, damper_running_ = false;
  std::string error_;
  std::string features_;
};

}  // namespace vdyn::wheel_input
