#include "vdyn/wheel_input/devices.h"

#include <SDL2/SDL.h>

#include <algorithm>
#include <cstdlib>
#include <stdexcept>

#include "vdyn/wheel_input/mapping.h"

namespace vdyn::wheel_input {
namespace {

const char* TypeName(SDL_JoystickType t) {
  switch (t) {
    case SDL_JOYSTICK_TYPE_GAMECONTROLLER:
      return "gamepad";
    case SDL_JOYSTICK_TYPE_WHEEL:
      return "wheel";
    case SDL_JOYSTICK_TYPE_ARCADE_STICK:
      return "arcade stick";
    case SDL_JOYSTICK_TYPE_FLIGHT_STICK:
      return "flight stick";
    case SDL_JOYSTICK_TYPE_DANCE_PAD:
      return "dance pad";
    case SDL_JOYSTICK_TYPE_GUITAR:
      return "guitar";
    case SDL_JOYSTICK_TYPE_DRUM_KIT:
      return "drum kit";
    case SDL_JOYSTICK_TYPE_ARCADE_PAD:
      return "arcade pad";
    case SDL_JOYSTICK_TYPE_THROTTLE:
      return "throttle";
    default:
      return "joystick";
  }
}

bool NamesIds(const pb::WheelMapping& m, std::uint16_t vid, std::uint16_t pid) {
  if (m.vendor_id() == 0 && m.product_ids_size() == 0) return true;
  if (m.vendor_id() != vid) return false;
  return m.product_ids_size() == 0 ||
         std::find(m.product_ids().begin(), m.product_ids().end(), pid) != m.product_ids().end();
}

}  // namespace

SdlContext::SdlContext(bool want_video) {
  SDL_SetHint(SDL_HINT_JOYSTICK_ALLOW_BACKGROUND_EVENTS, "1");
  SDL_SetHint(SDL_HINT_NO_SIGNAL_HANDLERS, "1");
  // The window is a few rectangles and letters drawn in software: blit it to X directly rather
  // than through an OpenGL texture (SDL's default on X11, which costs a GL context and, without a
  // GPU, llvmpipe's threads).
  SDL_SetHint(SDL_HINT_FRAMEBUFFER_ACCELERATION, "0");
  if (SDL_Init(SDL_INIT_JOYSTICK | SDL_INIT_HAPTIC | SDL_INIT_EVENTS) != 0) {
    // Haptic may be missing on a machine without force feedback support: joysticks still work.
    if (SDL_Init(SDL_INIT_JOYSTICK | SDL_INIT_EVENTS) != 0) {
      throw std::runtime_error(std::string("SDL_Init(joystick): ") + SDL_GetError());
    }
  }
  // Our loop reads the joysticks' state directly; their events would only fill the queue.
  SDL_JoystickEventState(SDL_IGNORE);
  if (want_video) {
    if (std::getenv("WAYLAND_DISPLAY") == nullptr && std::getenv("XDG_RUNTIME_DIR") == nullptr) {
      // No Wayland compositor can be reached: SDL's Wayland driver would only print a stray
      // "XDG_RUNTIME_DIR is invalid or not set" before our own message says what is missing.
      // (The SDL_VIDEODRIVER variable, as tests set it, still wins over this hint.)
      SDL_SetHint(SDL_HINT_VIDEODRIVER, "x11,offscreen");
    }
    if (SDL_InitSubSystem(SDL_INIT_VIDEO) == 0) {
      video_ = true;
      // Without a display SDL falls back to its offscreen driver: a window nobody sees or types
      // into. That counts as no display unless asked for by name (tests: SDL_VIDEODRIVER=dummy).
      const std::string driver = SDL_GetCurrentVideoDriver() ? SDL_GetCurrentVideoDriver() : "";
      const char* asked = std::getenv("SDL_VIDEODRIVER");
      if ((driver == "offscreen" || driver == "dummy") && (asked == nullptr || driver != asked)) {
        SDL_QuitSubSystem(SDL_INIT_VIDEO);
        video_ = false;
        video_error_ = "SDL found only its " + driver + " video driver; is DISPLAY set?";
      }
    } else {
      video_error_ = SDL_GetError();
    }
  }
}

SdlContext::~SdlContext() {
  SDL_Quit();
}

std::vector<DeviceInfo> ScanDevices(const std::optional<std::filesystem::path>& mapping_file) {
  std::optional<pb::WheelMapping> given;
  std::string given_problem;
  if (mapping_file) {
    try {
      given = ReadMappingFile(*mapping_file);
    } catch (const MappingError& e) {
      given_problem = e.what();
    }
  }
  SDL_JoystickUpdate();
  std::vector<DeviceInfo> out;
  const int n = SDL_NumJoysticks();
  for (int i = 0; i < n; ++i) {
    DeviceInfo d;
    d.index = i;
    d.instance_id = SDL_JoystickGetDeviceInstanceID(i);
    const char* name = SDL_JoystickNameForIndex(i);
    d.name = name ? name : "(unnamed)";
    d.vendor_id = SDL_JoystickGetDeviceVendor(i);
    d.product_id = SDL_JoystickGetDeviceProduct(i);
    const SDL_JoystickType type = SDL_JoystickGetDeviceType(i);
    d.type = TypeName(type);
    d.is_virtual = SDL_JoystickIsVirtual(i) == SDL_TRUE;
    if (SDL_Joystick* js = SDL_JoystickOpen(i)) {
      d.axes = SDL_JoystickNumAxes(js);
      d.buttons = SDL_JoystickNumButtons(js);
      d.hats = SDL_JoystickNumHats(js);
      d.haptic = SDL_JoystickIsHaptic(js) == SDL_TRUE;
      SDL_JoystickClose(js);
    }
    const std::filesystem::path user = DefaultMappingPath(d.vendor_id, d.product_id);
    std::error_code ec;
    if (mapping_file && (!given || NamesIds(*given, d.vendor_id, d.product_id))) {
      d.mapping_path = *mapping_file;
      if (given) {
        d.kind = DeviceInfo::Kind::kUserFile;
        d.mapping = *given;
      } else {
        d.kind = DeviceInfo::Kind::kBrokenFile;
        d.problem = given_problem;
      }
    } else if (std::filesystem::exists(user, ec)) {
      d.mapping_path = user;
      try {
        d.mapping = ReadMappingFile(user);
        d.kind = DeviceInfo::Kind::kUserFile;
      } catch (const MappingError& e) {
        d.kind = DeviceInfo::Kind::kBrokenFile;
        d.problem = e.what();
      }
    } else if (const pb::WheelMapping* m = FindBuiltinWheel(d.vendor_id, d.product_id)) {
      d.kind = DeviceInfo::Kind::kTable;
      d.mapping = *m;
    } else if (type == SDL_JOYSTICK_TYPE_WHEEL) {
      d.kind = DeviceInfo::Kind::kGeneric;
      d.mapping = GenericWheel(d.vendor_id, d.product_id, d.axes);
    }
    switch (d.kind) {
      case DeviceInfo::Kind::kUserFile:
        d.recognised_as = d.mapping.name() + " (user mapping " + d.mapping_path.string() + ")";
        break;
      case DeviceInfo::Kind::kTable:
        d.recognised_as = d.mapping.name() + " (built-in table)";
        break;
      case DeviceInfo::Kind::kGeneric:
        d.recognised_as = "a wheel not in the table (generic mapping: run vdyn-input calibrate)";
        break;
      case DeviceInfo::Kind::kBrokenFile:
        d.recognised_as = "broken mapping: " + d.problem;
        break;
      case DeviceInfo::Kind::kNotAWheel:
        d.recognised_as = "not a wheel";
        break;
    }
    out.push_back(std::move(d));
  }
  return out;
}

pb::WheelMapping FitToDevice(const pb::WheelMapping& in, int axes, int buttons, int pedal_axes,
                             std::vector<std::string>* notes) {
  pb::WheelMapping m = in;
  auto note = [&](const std::string& s) {
    if (notes) notes->push_back(s);
  };
  auto fit_optional = [&](pb::PedalAxis* p, const char* name) {
    if (!p->has_axis()) return;
    const int n = p->on_pedal_device() ? pedal_axes : axes;
    if (p->axis() >= n) {
      note(std::string(name) + " (axis " + std::to_string(p->axis()) +
           ") is not on this device: none");
      p->Clear();
    }
  };
  fit_optional(m.mutable_clutch(), "clutch");
  fit_optional(m.mutable_handbrake(), "handbrake");
  auto* b = m.mutable_buttons();
  const auto* refl = b->GetReflection();
  const auto* desc = b->GetDescriptor();
  for (int i = 0; i < desc->field_count(); ++i) {
    const auto* f = desc->field(i);
    if (refl->HasField(*b, f) && refl->GetInt32(*b, f) >= buttons) {
      note(std::string("button ") + f->name() + " (" + std::to_string(refl->GetInt32(*b, f)) +
           ") is not on this device: none");
      refl->ClearField(b, f);
    }
  }
  std::vector<std::string> why = ValidateMapping(m, axes, buttons);
  for (const pb::PedalAxis* p : {&m.throttle(), &m.brake()}) {
    if (p->has_axis() && p->on_pedal_device() && p->axis() >= pedal_axes) {
      why.push_back("a pedal is on axis " + std::to_string(p->axis()) +
                    " of the pedal device, which has " + std::to_string(pedal_axes));
    }
  }
  const bool combined = m.has_combined() && m.combined().has_axis();
  if (!combined && (!m.throttle().has_axis() || !m.brake().has_axis())) {
    why.push_back(
        "no throttle and brake axes (a base without pedal inputs needs a pedal set: "
        "vdyn-input calibrate --pedals N)");
  }
  if (!why.empty()) {
    std::string all;
    for (const auto& w : why) all += (all.empty() ? "" : "; ") + w;
    throw MappingError(m.name() + ": " + all);
  }
  return m;
}

std::unique_ptr<WheelDevice> WheelDevice::Open(const DeviceInfo& wheel,
                                               const std::vector<DeviceInfo>& devices,
                                               std::vector<std::string>* notes, std::string* why) {
  auto fail = [&](const std::string& s) {
    if (why) *why = s;
    return nullptr;
  };
  if (wheel.kind == DeviceInfo::Kind::kNotAWheel) return fail(wheel.name + ": not a wheel");
  if (wheel.kind == DeviceInfo::Kind::kBrokenFile) return fail(wheel.problem);
  std::unique_ptr<WheelDevice> d(new WheelDevice());
  d->info_ = wheel;
  d->joystick_ = SDL_JoystickOpen(wheel.index);
  if (d->joystick_ == nullptr) return fail(wheel.name + ": " + SDL_GetError());
  int pedal_axes = 0;
  const auto& m = wheel.mapping;
  if (m.pedal_vendor_id() != 0 || m.pedal_product_id() != 0) {
    for (const auto& p : devices) {
      if (p.vendor_id == m.pedal_vendor_id() && p.product_id == m.pedal_product_id() &&
          p.index != wheel.index) {
        d->pedals_ = SDL_JoystickOpen(p.index);
        if (d->pedals_ != nullptr) pedal_axes = SDL_JoystickNumAxes(d->pedals_);
        break;
      }
    }
    if (d->pedals_ == nullptr) {
      return fail(m.name() + ": its pedal set " +
                  VidPid(static_cast<std::uint16_t>(m.pedal_vendor_id()),
                         static_cast<std::uint16_t>(m.pedal_product_id())) +
                  " is not plugged in");
    }
  }
  try {
    d->mapping_ = FitToDevice(m, SDL_JoystickNumAxes(d->joystick_),
                              SDL_JoystickNumButtons(d->joystick_), pedal_axes, notes);
  } catch (const MappingError& e) {
    return fail(e.what());
  }
  return d;
}

WheelDevice::~WheelDevice() {
  if (pedals_ != nullptr) SDL_JoystickClose(pedals_);
  if (joystick_ != nullptr) SDL_JoystickClose(joystick_);
}

bool WheelDevice::attached() const {
  return SDL_JoystickGetAttached(joystick_) == SDL_TRUE &&
         (pedals_ == nullptr || SDL_JoystickGetAttached(pedals_) == SDL_TRUE);
}

void ReadJoysticks(SDL_Joystick* wheel, SDL_Joystick* pedals, RawFrame& f) {
  f.n_axes = std::min(SDL_JoystickNumAxes(wheel), RawFrame::kMaxAxes);
  for (int i = 0; i < f.n_axes; ++i)
    f.axes[static_cast<std::size_t>(i)] = SDL_JoystickGetAxis(wheel, i);
  f.n_buttons = std::min(SDL_JoystickNumButtons(wheel), RawFrame::kMaxButtons);
  for (int i = 0; i < f.n_buttons; ++i) {
    f.buttons[static_cast<std::size_t>(i)] = SDL_JoystickGetButton(wheel, i);
  }
  f.n_pedal_axes = 0;
  if (pedals != nullptr) {
    f.n_pedal_axes = std::min(SDL_JoystickNumAxes(pedals), RawFrame::kMaxAxes);
    for (int i = 0; i < f.n_pedal_axes; ++i) {
      f.pedal_axes[static_cast<std::size_t>(i)] = SDL_JoystickGetAxis(pedals, i);
    }
  }
}

void WheelDevice::Read(RawFrame& f) const {
  ReadJoysticks(joystick_, pedals_, f);
}

}  // namespace vdyn::wheel_input
