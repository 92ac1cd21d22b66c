#include "vdyn/wheel_input/sdl_haptic.h"

#include <SDL2/SDL_error.h>

#include <algorithm>
#include <cmath>

namespace vdyn::wheel_input {
namespace {

Uint32 LengthMs(base::Nanos length) {
  return static_cast<Uint32>(std::clamp<std::int64_t>(length.ns / 1'000'000, 1, 32767));
}

}  // namespace

std::unique_ptr<SdlHaptic> SdlHaptic::Open(SDL_Joystick* joystick, std::string* why) {
  if (SDL_JoystickIsHaptic(joystick) != SDL_TRUE) {
    if (why) *why = "the device has no force feedback";
    return nullptr;
  }
  SDL_Haptic* h = SDL_HapticOpenFromJoystick(joystick);
  if (h == nullptr) {
    if (why) *why = std::string("SDL_HapticOpenFromJoystick: ") + SDL_GetError();
    return nullptr;
  }
  std::unique_ptr<SdlHaptic> dev(new SdlHaptic(h));
  const unsigned int caps = SDL_HapticQuery(h);
  if ((caps & SDL_HAPTIC_CONSTANT) == 0) {
    if (why) *why = "the device has force feedback but no CONSTANT effect";
    return nullptr;
  }
  dev->features_ = "constant";
  if (caps & SDL_HAPTIC_AUTOCENTER) {
    // The server's torque is the whole feel: the device's own spring would add to it.
    if (SDL_HapticSetAutocenter(h, 0) == 0) dev->features_ += ", autocentre off";
  }
  if (caps & SDL_HAPTIC_GAIN) {
    if (SDL_HapticSetGain(h, 100) == 0) dev->features_ += ", gain 100 %";
  }
  auto& c = dev->constant_;
  c.type = SDL_HAPTIC_CONSTANT;
  c.constant.type = SDL_HAPTIC_CONSTANT;
  c.constant.direction.type = SDL_HAPTIC_STEERING_AXIS;
  c.constant.length = 100;
  c.constant.level = 0;
  dev->constant_id_ = SDL_HapticNewEffect(h, &c);
  if (dev->constant_id_ < 0) {
    if (why) *why = std::string("SDL_HapticNewEffect (constant): ") + SDL_GetError();
    return nullptr;
  }
  if (caps & SDL_HAPTIC_DAMPER) {
    auto& d = dev->damper_;
    d.type = SDL_HAPTIC_DAMPER;
    d.condition.type = SDL_HAPTIC_DAMPER;
    d.condition.direction.type = SDL_HAPTIC_STEERING_AXIS;
    d.condition.length = 100;
    d.condition.right_sat[0] = d.condition.left_sat[0] = 0xFFFF;
    dev->damper_id_ = SDL_HapticNewEffect(h, &d);
    if (dev->damper_id_ >= 0) dev->features_ += ", damper";
  }
  return dev;
}

SdlHaptic::~SdlHaptic() {
  SDL_HapticStopAll(haptic_);
  if (constant_id_ >= 0) SDL_HapticDestroyEffect(haptic_, constant_id_);
  if (damper_id_ >= 0) SDL_HapticDestroyEffect(haptic_, damper_id_);
  SDL_HapticClose(haptic_);
}

bool SdlHaptic::Play(int id, SDL_HapticEffect& effect, base::MonoTime& run_at, bool& running,
                     base::Nanos length) {
  if (SDL_HapticUpdateEffect(haptic_, id, &effect) != 0) {
    error_ = std::string("SDL_HapticUpdateEffect: ") + SDL_GetError();
    return false;
  }
  const base::MonoTime now = base::MonotonicNow();
  if (!running || now - run_at >= base::Nanos{length.ns / 2}) {
    if (SDL_HapticRunEffect(haptic_, id, 1) != 0) {
      error_ = std::string("SDL_HapticRunEffect: ") + SDL_GetError();
      return false;
    }
    run_at = now;
    running = true;
  }
  return true;
}

bool SdlHaptic::SetConstant(double level, base::Nanos length) {
  const double l = std::isfinite(level) ? std::clamp(level, -1.0, 1.0) : 0.0;
  constant_.constant.level = static_cast<Sint16>(std::lround(l * 32767.0));
  constant_.constant.length = LengthMs(length);
  return Play(constant_id_, constant_, constant_run_at_, constant_running_, length);
}

bool SdlHaptic::SetDamper(double coefficient, base::Nanos length) {
  if (damper_id_ < 0) return false;
  const double k = std::isfinite(coefficient) ? std::clamp(coefficient, 0.0, 1.0) : 0.0;
  const auto coeff = static_cast<Sint16>(std::lround(k * 32767.0));
  damper_.condition.right_coeff[0] = damper_.condition.left_coeff[0] = coeff;
  damper_.condition.length = LengthMs(length);
  return Play(damper_id_, damper_, damper_run_at_, damper_running_, length);
}

void SdlHaptic::Stop() {
  if (SDL_HapticStopAll(haptic_) != 0) error_ = std::string("SDL_HapticStopAll: ") + SDL_GetError();
  constant_running_ = false;
  damper_running_ = false;
}

}  // namespace vdyn::wheel_input
