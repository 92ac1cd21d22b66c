#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include <SDL2/SDL.h>
#include <fmt/format.h>

#include "vdyn/client/loop.h"
#include "vdyn/wheel_input/commands.h"
#include "vdyn/wheel_input/devices.h"
#include "vdyn/wheel_input/mapping.h"

namespace vdyn::wheel_input {
namespace {

using base::MonoTime;
using base::MonotonicNow;

void PrintDevices(const std::vector<DeviceInfo>& devices) {
  if (devices.empty()) {
    std::printf(
        "no joystick devices (plug in a wheel; on Linux the user needs read access to "
        "/dev/input/event*)\n");
    return;
  }
  for (const auto& d : devices) {
    std::printf("[%d] %s  %s  (%s%s)  %d axes, %d buttons, %d hats, force feedback: %s\n", d.index,
                d.name.c_str(), VidPid(d.vendor_id, d.product_id).c_str(), d.type.c_str(),
                d.is_virtual ? ", virtual" : "", d.axes, d.buttons, d.hats,
                d.haptic ? "yes" : "no");
    std::printf("    recognised as: %s\n", d.recognised_as.c_str());
    if (d.kind == DeviceInfo::Kind::kUserFile || d.kind == DeviceInfo::Kind::kTable ||
        d.kind == DeviceInfo::Kind::kGeneric) {
      const auto& m = d.mapping;
      std::string pedals;
      auto pedal = [&](const char* name, const pb::PedalAxis& p) {
        if (!p.has_axis()) return;
        pedals += std::string(" ") + name + "=" + (p.on_pedal_device() ? "p" : "") +
                  std::to_string(p.axis()) + (p.full() < p.rest() ? " (inverted)" : "");
      };
      pedal("throttle", m.throttle());
      pedal("brake", m.brake());
      pedal("clutch", m.clutch());
      pedal("handbrake", m.handbrake());
      if (m.has_combined() && m.combined().has_axis()) {
        pedals += " throttle+brake combined=" + std::to_string(m.combined().axis());
      }
      std::printf("    steering axis %d (%.0f deg lock to lock), pedals:%s, peak torque %.1f N*m\n",
                  m.steer().axis(), m.steer().range_deg(),
                  pedals.empty() ? " none" : pedals.c_str(), m.ffb().peak_torque_nm());
      if (!m.source().empty()) std::printf("    source: %s\n", m.source().c_str());
    }
  }
}

}  // namespace

int List(bool once, double seconds, const std::atomic<bool>& stop) {
  SdlContext sdl(false);
  auto devices = ScanDevices();
  PrintDevices(devices);
  if (once) return 0;
  std::printf("live values (Ctrl+C ends):\n");
  std::map<SDL_JoystickID, SDL_Joystick*> open;
  std::map<SDL_JoystickID, std::string> last_line;
  auto reopen = [&] {
    for (const auto& d : devices) {
      if (open.count(d.instance_id) == 0) {
        if (SDL_Joystick* js = SDL_JoystickOpen(d.index)) open[d.instance_id] = js;
      }
    }
  };
  reopen();
  const MonoTime start = MonotonicNow();
  MonoTime next_scan = start;
  client::FixedRateLoop clock(base::Milliseconds(100), start);
  while (!stop && (seconds <= 0 || (MonotonicNow() - start).seconds() < seconds)) {
    clock.Wait();
    SDL_JoystickUpdate();
    if (MonotonicNow() >= next_scan) {
      next_scan = MonotonicNow() + base::Milliseconds(500);
      auto now_devices = ScanDevices();
      for (auto it = open.begin(); it != open.end();) {
        if (SDL_JoystickGetAttached(it->second) != SDL_TRUE) {
          std::printf("unplugged: %s\n", SDL_JoystickName(it->second));
          SDL_JoystickClose(it->second);
          last_line.erase(it->first);
          it = open.erase(it);
        } else {
          ++it;
        }
      }
      for (const auto& d : now_devices) {
        if (open.count(d.instance_id) == 0) {
          std::printf("plugged in:\n");
          PrintDevices({d});
        }
      }
      devices = std::move(now_devices);
      reopen();
    }
    for (const auto& [id, js] : open) {
      std::string line = "  " + std::string(SDL_JoystickName(js)) + ":";
      for (int a = 0; a < SDL_JoystickNumAxes(js); ++a) {
        line += fmt::format(" a{}={}", a, SDL_JoystickGetAxis(js, a));
      }
      std::string pressed;
      for (int b = 0; b < SDL_JoystickNumButtons(js); ++b) {
        if (SDL_JoystickGetButton(js, b)) pressed += fmt::format(" {}", b);
      }
      line += "  buttons:" + (pressed.empty() ? std::string(" none") : pressed);
      if (line != last_line[id]) {
        std::printf("%s\n", line.c_str());
        std::fflush(stdout);
        last_line[id] = line;
      }
    }
  }
  for (auto& [id, js] : open) SDL_JoystickClose(js);
  return 0;
}

}  // namespace vdyn::wheel_input
