// `vdyn-input calibrate` as a state machine fed with raw frames, so a scripted session (tests,
// SDL virtual joysticks) runs it exactly as a person at the wheel does:
//
//   rest (Enter) -> turn fully left, hold -> fully right, hold -> press the throttle fully, hold
//   -> the brake -> [clutch] -> [handbrake] -> [left paddle] -> [right paddle] -> [cruise on/off,
//   up, down] -> [reset] -> [camera] -> [e-stop] -> [horn] -> [force-feedback direction] -> done
//
// Steps in brackets are optional: Enter (Skip) or a quiet while skips them. An axis step takes the
// axis that moved furthest from its rest value, once it has been held still for a moment at its
// extreme; the next step starts when everything is released. A brake found on the throttle's axis,
// on the other side of rest, makes the two combined pedals. The force-feedback step plays a small
// torque meant to turn the wheel left and watches which way it turns.
#pragma once

#include <string>
#include <vector>

#include "vdyn/base/time.h"
#include "vdyn/wheel_input/wheel_reader.h"
#include "vdyn/wheel_mapping.pb.h"

namespace vdyn::wheel_input {

class Calibrator {
 public:
  enum class Step {
    kRest,
    kSteerLeft,
    kSteerRight,
    kThrottle,
    kBrake,
    kClutch,
    kHandbrake,
    kPaddleLeft,
    kPaddleRight,
    kCruiseToggle,
    kCruiseUp,
    kCruiseDown,
    kReset,
    kCamera,
    kEstop,
    kHorn,
    kFfbDirection,
    kDone
  };
  struct Options {
    pb::WheelMapping base;  // name, ids, range and peak torque come from here
    std::uint16_t vendor_id = 0, product_id = 0;
    std::uint16_t pedal_vendor_id = 0, pedal_product_id = 0;  // with a separate pedal set
    double range_deg = 900;  // the hand wheel's lock-to-lock rotation (not measurable)
    double pedal_dead_zone = 0.02;
    double pedal_gamma = 1.0;
    double steer_dead_zone = 0.0;
    bool ffb = false;      // run the force-feedback direction step
    int threshold = 8000;  // raw units an axis must move to count
    base::Nanos hold = base::Milliseconds(500);
    base::Nanos optional_timeout = base::Seconds(20);  // 0: wait for Enter
    base::Nanos ffb_test = base::Milliseconds(1500);
    double ffb_test_level = 0.2;
  };

  explicit Calibrator(Options options);

  // Feeds the newest frame.
  void Feed(base::MonoTime now, const RawFrame& f);
  // Enter: captures the rest position, starts the force-feedback test, or skips an optional step.
  void Confirm(base::MonoTime now);
  // Skips an optional step (the force-feedback test included); required steps cannot be skipped.
  void Skip(base::MonoTime now);

  Step step() const { return step_; }
  bool done() const { return step_ == Step::kDone; }
  bool optional() const;
  // What the person should do now.
  std::string Prompt() const;
  // A short line after each step ("throttle: axis 2, 32767 at rest, -32768 pressed").
  const std::vector<std::string>& log() const { return log_; }
  // The level the force-feedback step asks the device for now ([-1, 1], positive left).
  double ffb_level() const { return ffb_level_; }
  // The mapping found (when done).
  pb::WheelMapping result() const { return result_; }

 private:
  struct AxisRef {
    bool pedal_device = false;
    int index = -1;
  };
  double Value(const RawFrame& f, AxisRef a) const;
  double RestValue(AxisRef a) const;
  void Next(base::MonoTime now);
  void AxisStep(base::MonoTime now, const RawFrame& f);
  void ButtonStep(base::MonoTime now, const RawFrame& f);
  void FfbStep(base::MonoTime now, const RawFrame& f);
  bool Released(const RawFrame& f) const;
  bool Used(AxisRef a) const;
  double SteerAngleDeg(const RawFrame& f) const;

  Options opt_;
  Step step_ = Step::kRest;
  base::MonoTime step_started_{};
  bool waiting_release_ = false;
  RawFrame rest_;
  bool have_rest_ = false;
  RawFrame last_;
  // The axis step in progress.
  AxisRef candidate_;
  double extreme_ = 0;
  base::MonoTime still_since_{};
  // Assigned so far.
  AxisRef steer_, throttle_, brake_;
  std::vector<AxisRef> used_;
  std::vector<int> used_buttons_;
  // Force-feedback test.
  bool ffb_running_ = false;
  base::MonoTime ffb_started_{};
  double ffb_start_angle_ = 0;
  double ffb_level_ = 0;
  pb::WheelMapping result_;
  std::vector<std::string> log_;
};

}  // namespace vdyn::wheel_input
