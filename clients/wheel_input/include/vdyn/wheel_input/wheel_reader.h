// From a wheel's raw axes and buttons to what the driver does: the hand-wheel angle, the pedals in
// [0, 1] and the buttons as DriverInput button bits, through a mapping (calibration, dead zones,
// curves, inversion, combined pedals). A raw value that is not a number holds the axis at its last
// good value (the throttle drops to 0); one outside the calibrated travel is clamped; both are
// counted. No SDL here: tests and other sources feed frames directly.
#pragma once

#include <array>
#include <cstdint>

#include "vdyn/wheel_mapping.pb.h"

namespace vdyn::wheel_input {

// One sample of a wheel (and its separate pedal set, if any), raw SDL units.
struct RawFrame {
  static constexpr int kMaxAxes = 64;
  static constexpr int kMaxButtons = 256;
  int n_axes = 0;
  std::array<double, kMaxAxes> axes{};
  int n_buttons = 0;
  std::array<std::uint8_t, kMaxButtons> buttons{};
  int n_pedal_axes = 0;
  std::array<double, kMaxAxes> pedal_axes{};
};

// What the driver does with the wheel.
struct WheelControls {
  double hand_angle_rad = 0;  // positive left
  double throttle = 0;        // [0, 1]
  double brake = 0;           // [0, 1]
  double clutch = 0;          // [0, 1], 1 = pedal down
  double handbrake = 0;       // [0, 1]
  std::uint32_t buttons = 0;  // vdyn.pb.Button bits held
  // No physical hand wheel (the keyboard): the angle stands for the road wheels' and is sent as
  // STEER_ROAD_WHEEL whatever the model, so the server's steering column does not filter it.
  bool road_wheel_only = false;
};

class WheelReader {
 public:
  explicit WheelReader(pb::WheelMapping mapping);

  WheelControls Read(const RawFrame& frame);

  const pb::WheelMapping& mapping() const { return mapping_; }
  // Raw values that were not numbers, and values outside an axis' calibrated travel (by more than
  // a tolerance of 2 % of the travel: sensor noise at the ends is not counted), since the start.
  std::uint64_t nonfinite() const { return nonfinite_; }
  std::uint64_t out_of_range() const { return out_of_range_; }

 private:
  // Travel in [0, 1] from rest to full; `last` holds the previous good value.
  double Pedal(const pb::PedalAxis& p, const RawFrame& f, double& last, bool zero_on_bad);
  bool Raw(const RawFrame& f, int axis, bool pedal_device, double& raw);

  pb::WheelMapping mapping_;
  WheelControls last_;
  std::uint64_t nonfinite_ = 0;
  std::uint64_t out_of_range_ = 0;
};

}  // namespace vdyn::wheel_input
