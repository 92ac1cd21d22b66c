// The rig loop of `vdyn-input drive` and `keyboard`, one thread, one tick per input period:
//
//   SDL events (keys, window; at their own rate) -> read the wheel (or step the keyboard ramps)
//   -> build the input -> publish it (the latency from the sample to the write is measured)
//   -> at the force-feedback rate: take the newest state and parameters, update the force
//   -> the window (at its own rate)
//
// A wheel unplugged mid-drive is reported and the input falls back to a safe neutral (no throttle,
// brake, steering held) until a device with the same USB ids is plugged in again. The loop talks
// to the domain through three small interfaces (dds_link.h implements them over DDS; tests can
// record instead).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "vdyn/base/time.h"
#include "vdyn/input.pb.h"
#include "vdyn/state.pb.h"
#include "vdyn/vehicle_params.pb.h"
#include "vdyn/wheel_input/controls.h"
#include "vdyn/wheel_input/devices.h"
#include "vdyn/wheel_input/ffb.h"
#include "vdyn/wheel_input/keyboard.h"
#include "vdyn/wheel_input/latency.h"
#include "vdyn/wheel_input/wheel_reader.h"
#include "vdyn/wheel_input/window.h"

namespace vdyn::wheel_input {

class InputSink {
 public:
  virtual ~InputSink() = default;
  // Writes one input read at `sampled`; false when it could not (last_error()).
  [[nodiscard]] virtual bool Publish(pb::DriverInput& msg, base::MonoTime sampled) = 0;
  virtual std::string last_error() const = 0;
};

class VehicleFeed {
 public:
  virtual ~VehicleFeed() = default;
  // Takes what has arrived (never blocks).
  virtual void Poll() = 0;
  // The newest state of the rig's vehicle and when it was taken, or nullptr.
  virtual const pb::VehicleState* state() const = 0;
  virtual base::MonoTime state_received() const = 0;
  virtual std::int64_t state_source_wall_ns() const = 0;
  virtual const pb::VehicleParams* params() const = 0;
};

class Resetter {
 public:
  virtual ~Resetter() = default;
  // Asks the server to reset the vehicle; returns at once (the answer is logged).
  virtual void RequestReset() = 0;
};

struct RigConfig {
  enum class Source { kAuto, kWheel, kKeyboard };
  Source source = Source::kAuto;  // kAuto: the first wheel found, else the keyboard
  std::optional<std::filesystem::path> mapping_file;
  int device_index = -1;              // SDL device index; -1: the first wheel
  std::optional<double> range_deg;    // overrides the mapping's rotation range
  std::optional<double> ffb_peak_nm;  // overrides the mapping's peak torque
  bool ffb = true;
  FfbParams ffb_params;  // peak and direction come from the mapping
  double ffb_rate_hz = 500;
  KeyboardParams keyboard;
  InputBuilderParams builder;
  double neutral_brake = 0.3;  // while the wheel is unplugged
  bool window = true;          // when SDL video is available (the keyboard needs it)
  double window_hz = 15;
  double events_hz = 100;  // SDL event pumping (keys, window): a key within 10 ms
  std::filesystem::path screenshot_dir = ".";  // F12
  std::uint32_t vehicle_id = 1;
  std::string source_id = "vdyn-input";
  base::Nanos replug_scan = base::Milliseconds(100);
};

using HapticFactory =
    std::function<std::unique_ptr<HapticDevice>(const WheelDevice& wheel, std::string* why)>;
// Opens SDL's haptic device of the wheel (SdlHaptic).
HapticFactory SdlHapticFactory();

class RigLoop {
 public:
  RigLoop(RigConfig config, SdlContext& sdl, InputSink& sink, VehicleFeed& feed, Resetter* resetter,
          HapticFactory haptics = SdlHapticFactory());
  ~RigLoop();

  // Finds and opens the wheel (or makes the keyboard window); throws std::runtime_error with the
  // reason when neither can be used.
  void Start();
  // One tick; false when the user closed the window.
  bool Tick(base::MonoTime now);

  bool using_wheel() const { return wheel_mode_; }
  bool wheel_attached() const { return wheel_ != nullptr; }
  const std::string& device_name() const { return device_name_; }
  const pb::DriverInput& last_input() const { return msg_; }
  const VehicleInfo& vehicle() const { return info_; }
  const InputBuilder& builder() const { return builder_; }
  const ForceFeedback* ffb() const { return ffb_.get(); }
  const WheelReader* reader() const { return reader_.get(); }
  KeyboardDriver& keyboard() { return keyboard_; }
  StatusWindow* window() { return window_.get(); }
  // Sample to DDS write, per input written.
  const LatencyHistogram& sample_to_write() const { return sample_to_write_; }
  std::uint64_t published() const { return published_; }
  std::uint64_t publish_errors() const { return publish_errors_; }
  std::uint64_t unplugs() const { return unplugs_; }
  std::uint64_t replugs() const { return replugs_; }
  // One line for the terminal, and the run's summary.
  std::string StatusLine() const;
  std::string Summary() const;
  // Takes a screenshot of the window at the next draw (PNG).
  void Screenshot(const std::filesystem::path& path);
  // Draws the window now (when there is one).
  void DrawNow() {
    if (window_) DrawWindow();
  }

 private:
  bool OpenWheel(const std::vector<DeviceInfo>& devices, const DeviceInfo& d, std::string* why);
  void PumpEvents(base::MonoTime now);
  void TryReplug(base::MonoTime now);
  void DrawWindow();

  RigConfig cfg_;
  SdlContext& sdl_;
  InputSink& sink_;
  VehicleFeed& feed_;
  Resetter* resetter_;
  HapticFactory haptics_;

  bool wheel_mode_ = false;
  std::unique_ptr<WheelDevice> wheel_;
  std::unique_ptr<WheelReader> reader_;
  std::unique_ptr<HapticDevice> haptic_;
  std::unique_ptr<ForceFeedback> ffb_;
  std::unique_ptr<StatusWindow> window_;
  std::string device_name_;
  std::uint16_t want_vendor_ = 0, want_product_ = 0;
  RawFrame frame_;
  KeyboardDriver keyboard_;
  InputBuilder builder_;
  VehicleInfo info_;
  pb::DriverInput msg_;
  bool quit_ = false;
  bool have_tick_ = false;
  base::MonoTime last_tick_{}, next_events_{}, next_ffb_{}, next_draw_{}, next_scan_{};
  std::uint64_t published_ = 0, publish_errors_ = 0, unplugs_ = 0, replugs_ = 0, resets_ = 0;
  LatencyHistogram sample_to_write_;
  std::string status_;
  std::uint64_t ffb_errors_said_ = 0;  // the force feedback's device errors logged so far
  base::MonoTime ffb_errors_next_say_{};
  bool status_alarm_ = false;
  double steer_fraction_ = 0;
  bool driving_ = false;
  bool silence_said_ = false;  // "no state ... for 2 s" logged
  int screenshots_ = 0;
};

}  // namespace vdyn::wheel_input
