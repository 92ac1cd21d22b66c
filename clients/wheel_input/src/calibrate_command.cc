// vdyn-input calibrate: the Calibrator (calibrate.h) fed from a device, prompting on the terminal.
#include <poll.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>

#include <SDL2/SDL.h>

#include "vdyn/client/loop.h"
#include "vdyn/wheel_input/calibrate.h"
#include "vdyn/wheel_input/commands.h"
#include "vdyn/wheel_input/devices.h"
#include "vdyn/wheel_input/mapping.h"
#include "vdyn/wheel_input/sdl_haptic.h"

namespace vdyn::wheel_input {
namespace {

using base::MonoTime;
using base::MonotonicNow;

// A line typed on the terminal, if one is waiting ("" for a bare Enter).
std::optional<std::string> ReadLineNow() {
  pollfd p{STDIN_FILENO, POLLIN, 0};
  if (poll(&p, 1, 0) <= 0 || (p.revents & POLLIN) == 0) return std::nullopt;
  std::string line;
  char ch = 0;
  while (read(STDIN_FILENO, &ch, 1) == 1 && ch != '\n') line += ch;
  return line;
}

}  // namespace

int Calibrate(const CalibrateOptions& o, const std::atomic<bool>& stop) {
  SdlContext sdl(false);
  const auto devices = ScanDevices();
  const DeviceInfo* wheel = nullptr;
  for (const auto& d : devices) {
    if (o.device >= 0 ? d.index == o.device : d.kind != DeviceInfo::Kind::kNotAWheel) {
      wheel = &d;
      break;
    }
  }
  if (wheel == nullptr && o.device < 0 && !devices.empty()) wheel = &devices.front();
  if (wheel == nullptr) {
    std::cerr << "vdyn-input: "
              << (o.device >= 0 ? "no device " + std::to_string(o.device) : "no device")
              << " to calibrate (vdyn-input list shows what SDL sees)\n";
    return 2;
  }
  const DeviceInfo* pedals = nullptr;
  if (o.pedals >= 0) {
    for (const auto& d : devices) {
      if (d.index == o.pedals && d.index != wheel->index) pedals = &d;
    }
    if (pedals == nullptr) {
      std::cerr << "vdyn-input: no pedal device " << o.pedals << "\n";
      return 2;
    }
  }
  SDL_Joystick* js = SDL_JoystickOpen(wheel->index);
  SDL_Joystick* pjs = pedals ? SDL_JoystickOpen(pedals->index) : nullptr;
  if (js == nullptr || (pedals && pjs == nullptr)) {
    std::cerr << "vdyn-input: cannot open the device: " << SDL_GetError() << "\n";
    return 2;
  }
  Calibrator::Options opt;
  opt.base =
      wheel->kind == DeviceInfo::Kind::kNotAWheel || wheel->kind == DeviceInfo::Kind::kBrokenFile
          ? GenericWheel(wheel->vendor_id, wheel->product_id, wheel->axes)
          : wheel->mapping;
  if (wheel->kind == DeviceInfo::Kind::kNotAWheel) opt.base.set_name(wheel->name);
  opt.vendor_id = wheel->vendor_id;
  opt.product_id = wheel->product_id;
  if (pedals) {
    opt.pedal_vendor_id = pedals->vendor_id;
    opt.pedal_product_id = pedals->product_id;
  }
  opt.range_deg = o.range_deg > 0
                      ? o.range_deg
                      : (opt.base.steer().has_range_deg() ? opt.base.steer().range_deg() : 900.0);
  opt.pedal_dead_zone = o.pedal_dead_zone;
  opt.pedal_gamma = o.pedal_gamma;
  opt.steer_dead_zone = o.steer_dead_zone;
  std::unique_ptr<SdlHaptic> haptic;
  if (!o.no_ffb_test) {
    std::string why;
    haptic = SdlHaptic::Open(js, &why);
    if (!haptic) std::printf("(force-feedback direction test skipped: %s)\n", why.c_str());
  }
  opt.ffb = haptic != nullptr;
  Calibrator cal(opt);
  std::printf("Calibrating [%d] %s %s; %s\n", wheel->index, wheel->name.c_str(),
              VidPid(wheel->vendor_id, wheel->product_id).c_str(),
              pedals ? ("pedal set [" + std::to_string(pedals->index) + "] " + pedals->name).c_str()
                     : "pedals on the wheel");
  std::printf(
      "The wheel's rotation lock to lock is taken as %.0f degrees (--range-deg changes it).\n",
      opt.range_deg);
  const MonoTime start = MonotonicNow();
  client::FixedRateLoop clock(base::Milliseconds(5), start);
  std::string prompt;
  std::size_t logged = 0;
  RawFrame frame;
  double playing = 0;
  while (!stop && !cal.done()) {
    const auto tick = clock.Wait();
    if ((tick.now - start).seconds() > o.timeout_s) {
      std::cerr << "vdyn-input: calibration not finished within " << o.timeout_s << " s\n";
      if (haptic) haptic->Stop();
      return 1;
    }
    SDL_JoystickUpdate();
    if (SDL_JoystickGetAttached(js) != SDL_TRUE) {
      std::cerr << "vdyn-input: the device was unplugged; calibration abandoned\n";
      return 1;
    }
    ReadJoysticks(js, pjs, frame);
    cal.Feed(tick.now, frame);
    if (auto line = ReadLineNow()) {
      if (*line == "s" || *line == "S") {
        cal.Skip(tick.now);
      } else {
        cal.Confirm(tick.now);
      }
    }
    if (haptic) {
      const double level = cal.ffb_level();
      if (level != 0.0) {
        haptic->SetConstant(level, base::Milliseconds(200));
      } else if (playing != 0.0) {
        haptic->Stop();
      }
      playing = level;
    }
    for (; logged < cal.log().size(); ++logged)
      std::printf("  ok: %s\n", cal.log()[logged].c_str());
    if (cal.Prompt() != prompt && !cal.done()) {
      prompt = cal.Prompt();
      std::printf("> %s\n", prompt.c_str());
    }
    std::fflush(stdout);
  }
  if (haptic) haptic->Stop();
  if (!cal.done()) return 1;
  const pb::WheelMapping result = cal.result();
  const auto why = ValidateMapping(result, wheel->axes, wheel->buttons);
  if (!why.empty()) {
    std::cerr << "vdyn-input: the calibration cannot be used:";
    for (const auto& w : why) std::cerr << "\n  " << w;
    std::cerr << "\n";
    return 1;
  }
  const std::filesystem::path out = o.out.empty()
                                        ? DefaultMappingPath(wheel->vendor_id, wheel->product_id)
                                        : std::filesystem::path(o.out);
  WriteMappingFile(out, result);
  std::printf("\nwrote %s:\n%s", out.string().c_str(), DumpMappingText(result).c_str());
  if (js) SDL_JoystickClose(js);
  if (pjs) SDL_JoystickClose(pjs);
  return 0;
}

}  // namespace vdyn::wheel_input
