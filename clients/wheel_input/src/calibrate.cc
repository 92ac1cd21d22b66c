#include "vdyn/wheel_input/calibrate.h"

#include <algorithm>
#include <cmath>

#include "vdyn/wheel_input/mapping.h"

namespace vdyn::wheel_input {
namespace {

// An axis held within this many raw units of its extreme counts as still (2 % of full scale).
constexpr double kStill = 1311.0;

bool AxisStepId(Calibrator::Step s) {
  using S = Calibrator::Step;
  return s == S::kSteerLeft || s == S::kSteerRight || s == S::kThrottle || s == S::kBrake ||
         s == S::kClutch || s == S::kHandbrake;
}

bool ButtonStepId(Calibrator::Step s) {
  using S = Calibrator::Step;
  return s >= S::kPaddleLeft && s <= S::kHorn;
}

const char* StepName(Calibrator::Step s) {
  using S = Calibrator::Step;
  switch (s) {
    case S::kRest:
      return "rest";
    case S::kSteerLeft:
      return "steering left";
    case S::kSteerRight:
      return "steering right";
    case S::kThrottle:
      return "throttle";
    case S::kBrake:
      return "brake";
    case S::kClutch:
      return "clutch";
    case S::kHandbrake:
      return "handbrake";
    case S::kPaddleLeft:
      return "left paddle";
    case S::kPaddleRight:
      return "right paddle";
    case S::kCruiseToggle:
      return "cruise on/off";
    case S::kCruiseUp:
      return "cruise up";
    case S::kCruiseDown:
      return "cruise down";
    case S::kReset:
      return "reset";
    case S::kCamera:
      return "camera";
    case S::kEstop:
      return "e-stop";
    case S::kHorn:
      return "horn";
    case S::kFfbDirection:
      return "force-feedback direction";
    case S::kDone:
      return "done";
  }
  return "?";
}

}  // namespace

Calibrator::Calibrator(Options options) : opt_(std::move(options)) {
  result_ = opt_.base;
  result_.clear_steer();
  result_.clear_throttle();
  result_.clear_brake();
  result_.clear_clutch();
  result_.clear_handbrake();
  result_.clear_combined();
  result_.clear_buttons();
  result_.clear_product_ids();
  result_.set_vendor_id(opt_.vendor_id);
  result_.add_product_ids(opt_.product_id);
  if (result_.name().empty()) result_.set_name("wheel " + VidPid(opt_.vendor_id, opt_.product_id));
  result_.set_source("vdyn-input calibrate");
  result_.set_pedal_vendor_id(0);
  result_.set_pedal_product_id(0);
}

bool Calibrator::optional() const {
  return step_ == Step::kClutch || step_ == Step::kHandbrake || ButtonStepId(step_) ||
         step_ == Step::kFfbDirection;
}

std::string Calibrator::Prompt() const {
  const std::string skip = " (optional: press Enter to skip)";
  if (waiting_release_ && step_ != Step::kDone) {
    if (step_ == Step::kSteerRight)
      return "Now turn the wheel fully to the RIGHT and hold it there";
    return "Release everything (wheel centred, pedals up, no button pressed)";
  }
  switch (step_) {
    case Step::kRest:
      return "Centre the wheel, release every pedal and button, then press Enter";
    case Step::kSteerLeft:
      return "Turn the wheel fully to the LEFT and hold it there";
    case Step::kSteerRight:
      return "Now turn the wheel fully to the RIGHT and hold it there";
    case Step::kThrottle:
      return "Press the THROTTLE pedal fully and hold it";
    case Step::kBrake:
      return "Press the BRAKE pedal fully and hold it";
    case Step::kClutch:
      return "Press the CLUTCH pedal fully and hold it" + skip;
    case Step::kHandbrake:
      return "Pull the HANDBRAKE fully and hold it" + skip;
    case Step::kPaddleLeft:
      return "Press the LEFT paddle (shift down)" + skip;
    case Step::kPaddleRight:
      return "Press the RIGHT paddle (shift up)" + skip;
    case Step::kCruiseToggle:
      return "Press the button for CRUISE CONTROL on/off" + skip;
    case Step::kCruiseUp:
      return "Press the button for cruise SET SPEED UP" + skip;
    case Step::kCruiseDown:
      return "Press the button for cruise SET SPEED DOWN" + skip;
    case Step::kReset:
      return "Press the button to RESET the vehicle" + skip;
    case Step::kCamera:
      return "Press the button for the CAMERA" + skip;
    case Step::kEstop:
      return "Press the button for the EMERGENCY STOP of force feedback" + skip;
    case Step::kHorn:
      return "Press the button for the HORN" + skip;
    case Step::kFfbDirection:
      return ffb_running_ ? "Hands off: a small force is turning the wheel..."
                          : "Let go of the wheel (a small force will turn it), then press Enter; "
                            "type s and Enter to skip";
    case Step::kDone:
      return "Done";
  }
  return "";
}

double Calibrator::Value(const RawFrame& f, AxisRef a) const {
  const int n = a.pedal_device ? f.n_pedal_axes : f.n_axes;
  if (a.index < 0 || a.index >= n) return RestValue(a);
  const double v = a.pedal_device ? f.pedal_axes[static_cast<std::size_t>(a.index)]
                                  : f.axes[static_cast<std::size_t>(a.index)];
  return std::isfinite(v) ? v : RestValue(a);
}

double Calibrator::RestValue(AxisRef a) const {
  const int n = a.pedal_device ? rest_.n_pedal_axes : rest_.n_axes;
  if (a.index < 0 || a.index >= n) return 0.0;
  const double v = a.pedal_device ? rest_.pedal_axes[static_cast<std::size_t>(a.index)]
                                  : rest_.axes[static_cast<std::size_t>(a.index)];
  return std::isfinite(v) ? v : 0.0;
}

bool Calibrator::Used(AxisRef a) const {
  return std::any_of(used_.begin(), used_.end(), [&](const AxisRef& u) {
    return u.pedal_device == a.pedal_device && u.index == a.index;
  });
}

bool Calibrator::Released(const RawFrame& f) const {
  for (int dev = 0; dev < 2; ++dev) {
    const int n = dev ? f.n_pedal_axes : f.n_axes;
    for (int i = 0; i < n; ++i) {
      const AxisRef a{dev == 1, i};
      if (std::abs(Value(f, a) - RestValue(a)) > opt_.threshold / 2.0) return false;
    }
  }
  for (int i = 0; i < f.n_buttons; ++i) {
    if (f.buttons[static_cast<std::size_t>(i)] && !rest_.buttons[static_cast<std::size_t>(i)]) {
      return false;
    }
  }
  return true;
}

double Calibrator::SteerAngleDeg(const RawFrame& f) const {
  const auto& s = result_.steer();
  const double t = (Value(f, steer_) - s.left()) / static_cast<double>(s.right() - s.left());
  return (1.0 - 2.0 * t) * 0.5 * s.range_deg();
}

void Calibrator::Next(base::MonoTime now) {
  auto next = static_cast<Step>(static_cast<int>(step_) + 1);
  if (next == Step::kFfbDirection && !opt_.ffb) next = Step::kDone;
  step_ = next;
  candidate_ = {};
  waiting_release_ = step_ != Step::kDone && step_ != Step::kFfbDirection;
  step_started_ = now;
  ffb_running_ = false;
  ffb_level_ = 0;
}

void Calibrator::Confirm(base::MonoTime now) {
  if (step_ == Step::kRest) {
    if (last_.n_axes == 0) return;  // no frame yet
    rest_ = last_;
    have_rest_ = true;
    log_.push_back(
        "rest position taken (" + std::to_string(rest_.n_axes) + " axes" +
        (rest_.n_pedal_axes ? ", " + std::to_string(rest_.n_pedal_axes) + " pedal-set axes" : "") +
        ")");
    Next(now);
    waiting_release_ = false;
    return;
  }
  if (step_ == Step::kFfbDirection && !ffb_running_) {
    ffb_running_ = true;
    ffb_started_ = now;
    ffb_start_angle_ = SteerAngleDeg(last_);
    ffb_level_ = opt_.ffb_test_level;
    return;
  }
  if (optional() && step_ != Step::kFfbDirection) Skip(now);
}

void Calibrator::Skip(base::MonoTime now) {
  if (!optional() || step_ == Step::kDone) return;
  log_.push_back(std::string(StepName(step_)) + ": skipped");
  Next(now);
}

void Calibrator::Feed(base::MonoTime now, const RawFrame& f) {
  last_ = f;
  if (!have_rest_ || step_ == Step::kDone) return;
  if (waiting_release_) {
    const bool released =
        step_ == Step::kSteerRight
            ? std::abs(Value(f, steer_) - RestValue(steer_)) < opt_.threshold / 2.0
            : Released(f);
    if (released) {
      waiting_release_ = false;
      step_started_ = now;
    }
    return;
  }
  if (step_ == Step::kFfbDirection) {
    FfbStep(now, f);
    return;
  }
  if (optional() && opt_.optional_timeout.ns > 0 && candidate_.index < 0 &&
      now - step_started_ >= opt_.optional_timeout) {
    log_.push_back(std::string(StepName(step_)) + ": nothing pressed, skipped");
    Next(now);
    return;
  }
  if (AxisStepId(step_)) AxisStep(now, f);
  if (ButtonStepId(step_)) ButtonStep(now, f);
}

void Calibrator::AxisStep(base::MonoTime now, const RawFrame& f) {
  // The candidates of this step and the axis that moved furthest among them.
  AxisRef best;
  double best_dev = 0;
  auto consider = [&](AxisRef a) {
    const double dev = std::abs(Value(f, a) - RestValue(a));
    if (dev > best_dev) {
      best_dev = dev;
      best = a;
    }
  };
  if (step_ == Step::kSteerRight) {
    const double left_side = result_.steer().left() - RestValue(steer_);
    const double v = Value(f, steer_) - RestValue(steer_);
    if ((v > 0) != (left_side > 0)) consider(steer_);
  } else {
    for (int dev = 0; dev < 2; ++dev) {
      if (dev == 1 && step_ == Step::kSteerLeft) break;
      const int n = dev ? f.n_pedal_axes : f.n_axes;
      for (int i = 0; i < n; ++i) {
        const AxisRef a{dev == 1, i};
        const bool combined_brake = step_ == Step::kBrake &&
                                    a.pedal_device == throttle_.pedal_device &&
                                    a.index == throttle_.index;
        if (combined_brake) {
          // The brake on the throttle's axis must move the other way.
          const double t_side = result_.throttle().full() - RestValue(a);
          if ((Value(f, a) - RestValue(a) > 0) == (t_side > 0)) continue;
        } else if (Used(a)) {
          continue;
        }
        consider(a);
      }
    }
  }
  if (best_dev < opt_.threshold) {
    candidate_ = {};
    return;
  }
  const double v = Value(f, best);
  if (best.index != candidate_.index || best.pedal_device != candidate_.pedal_device) {
    candidate_ = best;
    extreme_ = v;
    still_since_ = now;
    return;
  }
  const double rest = RestValue(best);
  if (std::abs(v - rest) > std::abs(extreme_ - rest)) {
    if (std::abs(v - extreme_) > kStill) still_since_ = now;
    extreme_ = v;
  } else if (std::abs(v - extreme_) > kStill) {
    still_since_ = now;
  }
  if (now - still_since_ < opt_.hold) return;

  const int raw_rest = static_cast<int>(std::lround(rest));
  const int raw_full = static_cast<int>(std::lround(extreme_));
  auto where = [&](AxisRef a) {
    return std::string(a.pedal_device ? "pedal-set axis " : "axis ") + std::to_string(a.index);
  };
  auto pedal = [&](pb::PedalAxis* p, const char* name) {
    p->set_axis(best.index);
    p->set_rest(raw_rest);
    p->set_full(raw_full);
    p->set_dead_zone(opt_.pedal_dead_zone);
    p->set_gamma(opt_.pedal_gamma);
    if (best.pedal_device) p->set_on_pedal_device(true);
    log_.push_back(std::string(name) + ": " + where(best) + ", " + std::to_string(raw_rest) +
                   " at rest, " + std::to_string(raw_full) + " pressed" +
                   (raw_full < raw_rest ? " (rests at the high end)" : ""));
  };
  switch (step_) {
    case Step::kSteerLeft:
      steer_ = best;
      result_.mutable_steer()->set_axis(best.index);
      result_.mutable_steer()->set_left(raw_full);
      log_.push_back("steering: " + where(best) + ", " + std::to_string(raw_full) +
                     " at the left lock");
      break;
    case Step::kSteerRight:
      result_.mutable_steer()->set_right(raw_full);
      result_.mutable_steer()->set_range_deg(opt_.range_deg);
      result_.mutable_steer()->set_dead_zone(opt_.steer_dead_zone);
      log_.push_back("steering: " + std::to_string(raw_full) + " at the right lock, " +
                     std::to_string(static_cast<int>(opt_.range_deg)) + " degrees lock to lock");
      break;
    case Step::kThrottle:
      throttle_ = best;
      pedal(result_.mutable_throttle(), "throttle");
      break;
    case Step::kBrake:
      if (best.index == throttle_.index && best.pedal_device == throttle_.pedal_device) {
        auto* c = result_.mutable_combined();
        c->set_axis(best.index);
        c->set_rest(raw_rest);
        c->set_throttle_full(result_.throttle().full());
        c->set_brake_full(raw_full);
        c->set_dead_zone(opt_.pedal_dead_zone);
        if (best.pedal_device) c->set_on_pedal_device(true);
        result_.clear_throttle();
        log_.push_back("brake: on the throttle's " + where(best) + " (combined pedals), " +
                       std::to_string(raw_full) + " pressed");
      } else {
        brake_ = best;
        pedal(result_.mutable_brake(), "brake");
      }
      break;
    case Step::kClutch:
      pedal(result_.mutable_clutch(), "clutch");
      break;
    case Step::kHandbrake:
      pedal(result_.mutable_handbrake(), "handbrake");
      break;
    default:
      break;
  }
  used_.push_back(best);
  if (best.pedal_device) {
    result_.set_pedal_vendor_id(opt_.pedal_vendor_id);
    result_.set_pedal_product_id(opt_.pedal_product_id);
  }
  Next(now);
}

void Calibrator::ButtonStep(base::MonoTime now, const RawFrame& f) {
  for (int i = 0; i < f.n_buttons; ++i) {
    const auto u = static_cast<std::size_t>(i);
    if (!f.buttons[u] || rest_.buttons[u]) continue;
    if (std::find(used_buttons_.begin(), used_buttons_.end(), i) != used_buttons_.end()) continue;
    auto* b = result_.mutable_buttons();
    const char* name = "";
    switch (step_) {
      case Step::kPaddleLeft:
        b->set_paddle_left(i);
        name = "left paddle";
        break;
      case Step::kPaddleRight:
        b->set_paddle_right(i);
        name = "right paddle";
        break;
      case Step::kCruiseToggle:
        b->set_cruise_toggle(i);
        name = "cruise on/off";
        break;
      case Step::kCruiseUp:
        b->set_cruise_up(i);
        name = "cruise up";
        break;
      case Step::kCruiseDown:
        b->set_cruise_down(i);
        name = "cruise down";
        break;
      case Step::kReset:
        b->set_reset(i);
        name = "reset";
        break;
      case Step::kCamera:
        b->set_camera(i);
        name = "camera";
        break;
      case Step::kEstop:
        b->set_estop(i);
        name = "e-stop";
        break;
      case Step::kHorn:
        b->set_horn(i);
        name = "horn";
        break;
      default:
        return;
    }
    used_buttons_.push_back(i);
    log_.push_back(std::string(name) + ": button " + std::to_string(i));
    Next(now);
    return;
  }
}

void Calibrator::FfbStep(base::MonoTime now, const RawFrame& f) {
  if (!ffb_running_) {
    if (opt_.optional_timeout.ns > 0 && now - step_started_ >= opt_.optional_timeout) {
      log_.push_back("force-feedback direction: nothing confirmed, skipped");
      Next(now);
    }
    return;
  }
  const double moved = SteerAngleDeg(f) - ffb_start_angle_;
  if (std::abs(moved) > 3.0) {
    const bool invert = moved < 0;
    result_.mutable_ffb()->set_invert(invert);
    log_.push_back(std::string("force feedback: a positive level turned the wheel ") +
                   (invert ? "right: inverted" : "left: as expected"));
    Next(now);
    return;
  }
  if (now - ffb_started_ >= opt_.ffb_test) {
    log_.push_back("force feedback: the wheel did not move; its direction is left as it was");
    Next(now);
  }
}

}  // namespace vdyn::wheel_input
