// The devices SDL sees, what each is recognised as (a user mapping file, the built-in table, a
// generic wheel, or not a wheel), and an opened wheel (with its separate pedal set, if the mapping
// names one) read into raw frames. Hot-plug: attached() turns false when a device is unplugged;
// the rig then looks for it again by its USB ids.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <SDL2/SDL_joystick.h>

#include "vdyn/wheel_input/wheel_reader.h"
#include "vdyn/wheel_mapping.pb.h"

namespace vdyn::wheel_input {

// SDL's joystick and haptic subsystems (and video, for the window), initialised for a rig:
// joystick values are read whether or not a window of ours has the keyboard focus (SDL drops them
// otherwise), and SDL does not install its own signal handlers. One per process.
class SdlContext {
 public:
  // Throws std::runtime_error when the joystick subsystem cannot start. Video is optional: when
  // it cannot start, video() is false and video_error() says why.
  explicit SdlContext(bool want_video);
  ~SdlContext();
  SdlContext(const SdlContext&) = delete;
  SdlContext& operator=(const SdlContext&) = delete;
  bool video() const { return video_; }
  const std::string& video_error() const { return video_error_; }

 private:
  bool video_ = false;
  std::string video_error_;
};

struct DeviceInfo {
  enum class Kind { kUserFile, kTable, kGeneric, kBrokenFile, kNotAWheel };
  int index = -1;  // SDL device index now
  SDL_JoystickID instance_id = -1;
  std::string name;
  std::uint16_t vendor_id = 0, product_id = 0;
  std::string type;  // SDL's guess: "wheel", "gamepad", ...
  bool is_virtual = false;
  int axes = 0, buttons = 0, hats = 0;
  bool haptic = false;
  Kind kind = Kind::kNotAWheel;
  std::string recognised_as;           // "Logitech G29 (built-in table)", "user mapping FILE", ...
  pb::WheelMapping mapping;            // for kUserFile, kTable, kGeneric
  std::filesystem::path mapping_path;  // the user file looked for (kUserFile, kBrokenFile)
  std::string problem;                 // kBrokenFile: why the file cannot be used
};


// Every device SDL sees now, recognised. `mapping_file`, when given, is the mapping for every
// device whose USB ids it names (or for any device, when it names none).
std::vector<DeviceInfo> ScanDevices(const std::optional<std::filesystem::path>& mapping_file = {});

// A mapping trimmed to a device: optional pedals and buttons the device does not have are dropped
// (each noted); what remains is checked. Throws MappingError when steering, throttle or brake
// cannot be read from it.
pb::WheelMapping FitToDevice(const pb::WheelMapping& m, int axes, int buttons, int pedal_axes,
                             std::vector<std::string>* notes);

// Reads the current values of a joystick (and a pedal set, may be null) after SDL_JoystickUpdate.
void ReadJoysticks(SDL_Joystick* wheel, SDL_Joystick* pedals, RawFrame& frame);

class WheelDevice {
 public:
  // Opens the wheel at `wheel` (and its pedal set, found by the mapping's pedal ids among
  // `devices`) with the fitted mapping; nullptr and the reason when it cannot.
  static std::unique_ptr<WheelDevice> Open(const DeviceInfo& wheel,
                                           const std::vector<DeviceInfo>& devices,
                                           std::vector<std::string>* notes, std::string* why);
  ~WheelDevice();
  WheelDevice(const WheelDevice&) = delete;
  WheelDevice& operator=(const WheelDevice&) = delete;

  // Both devices still plugged in.
  bool attached() const;
  // The current values (after SDL_JoystickUpdate).
  void Read(RawFrame& frame) const;

  SDL_Joystick* joystick() const { return joystick_; }
  const DeviceInfo& info() const { return info_; }
  const pb::WheelMapping& mapping() const { return mapping_; }
  bool has_pedal_device() const { return pedals_ != nullptr; }

 private:
  WheelDevice() = default;
  DeviceInfo info_;
  pb::WheelMapping mapping_;
  SDL_Joystick* joystick_ = nullptr;
  SDL_Joystick* pedals_ = nullptr;
};

}  // namespace vdyn::wheel_input
