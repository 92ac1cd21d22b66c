#include "vdyn/wheel_input/wheel_reader.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "vdyn/input.pb.h"

namespace vdyn::wheel_input {
namespace {

constexpr double kTolerance = 0.02;

// Dead zone at the start of a [0, 1] travel, rescaled so the rest of the travel still reaches 1.
double DeadZone(double t, double dz) {
  if (t <= dz) return 0.0;
  return (t - dz) / (1.0 - dz);
}

}  // namespace

WheelReader::WheelReader(pb::WheelMapping mapping) : mapping_(std::move(mapping)) {}

bool WheelReader::Raw(const RawFrame& f, int axis, bool pedal_device, double& raw) {
  const int n = pedal_device ? f.n_pedal_axes : f.n_axes;
  if (axis < 0 || axis >= n || axis >= RawFrame::kMaxAxes) return false;
  raw = pedal_device ? f.pedal_axes[static_cast<std::size_t>(axis)]
                     : f.axes[static_cast<std::size_t>(axis)];
  if (!std::isfinite(raw)) {
    ++nonfinite_;
    return false;
  }
  return true;
}

double WheelReader::Pedal(const pb::PedalAxis& p, const RawFrame& f, double& last,
                          bool zero_on_bad) {
  if (!p.has_axis()) return 0.0;
  double raw = 0;
  if (!Raw(f, p.axis(), p.on_pedal_device(), raw)) {
    if (zero_on_bad) last = 0.0;
    return last;
  }
  double t = (raw - p.rest()) / static_cast<double>(p.full() - p.rest());
  if (t < -kTolerance || t > 1.0 + kTolerance) ++out_of_range_;
  t = std::clamp(t, 0.0, 1.0);
  t = DeadZone(t, p.dead_zone());
  const double gamma = p.has_gamma() ? p.gamma() : 1.0;
  last = gamma == 1.0 ? t : std::pow(t, gamma);
  return last;
}

WheelControls WheelReader::Read(const RawFrame& f) {
  WheelControls c = last_;
  const auto& s = mapping_.steer();
  double raw = 0;
  if (Raw(f, s.axis(), false, raw)) {
    // 0 at the left lock, 1 at the right lock; centred: +1 left, -1 right.
    double t = (raw - s.left()) / static_cast<double>(s.right() - s.left());
    if (t < -kTolerance || t > 1.0 + kTolerance) ++out_of_range_;
    t = std::clamp(t, 0.0, 1.0);
    double centred = 1.0 - 2.0 * t;
    const double dz = s.dead_zone();
    centred = std::copysign(DeadZone(std::abs(centred), dz), centred);
    c.hand_angle_rad = centred * 0.5 * s.range_deg() * std::numbers::pi / 180.0;
  }
  if (mapping_.has_combined() && mapping_.combined().has_axis()) {
    const auto& cb = mapping_.combined();
    if (Raw(f, cb.axis(), cb.on_pedal_device(), raw)) {
      const double to_throttle =
          (raw - cb.rest()) / static_cast<double>(cb.throttle_full() - cb.rest());
      const double to_brake = (raw - cb.rest()) / static_cast<double>(cb.brake_full() - cb.rest());
      if (to_throttle > 1.0 + kTolerance || to_brake > 1.0 + kTolerance) ++out_of_range_;
      c.throttle = DeadZone(std::clamp(to_throttle, 0.0, 1.0), cb.dead_zone());
      c.brake = DeadZone(std::clamp(to_brake, 0.0, 1.0), cb.dead_zone());
    } else {
      c.throttle = 0.0;  // the brake holds its last good value
    }
  } else {
    c.throttle = Pedal(mapping_.throttle(), f, last_.throttle, true);
    c.brake = Pedal(mapping_.brake(), f, last_.brake, false);
  }
  c.clutch = Pedal(mapping_.clutch(), f, last_.clutch, false);
  c.handbrake = Pedal(mapping_.handbrake(), f, last_.handbrake, false);

  const auto& b = mapping_.buttons();
  auto held = [&](bool has, int index) {
    return has && index >= 0 && index < f.n_buttons && index < RawFrame::kMaxButtons &&
           f.buttons[static_cast<std::size_t>(index)] != 0;
  };
  std::uint32_t bits = 0;
  if (held(b.has_paddle_left(), b.paddle_left())) bits |= pb::BUTTON_PADDLE_LEFT;
  if (held(b.has_paddle_right(), b.paddle_right())) bits |= pb::BUTTON_PADDLE_RIGHT;
  if (held(b.has_cruise_toggle(), b.cruise_toggle())) bits |= pb::BUTTON_CRUISE_TOGGLE;
  if (held(b.has_cruise_up(), b.cruise_up())) bits |= pb::BUTTON_CRUISE_UP;
  if (held(b.has_cruise_down(), b.cruise_down())) bits |= pb::BUTTON_CRUISE_DOWN;
  if (held(b.has_reset(), b.reset())) bits |= pb::BUTTON_RESET;
  if (held(b.has_camera(), b.camera())) bits |= pb::BUTTON_CAMERA;
  if (held(b.has_estop(), b.estop())) bits |= pb::BUTTON_ESTOP;
  if (held(b.has_horn(), b.horn())) bits |= pb::BUTTON_HORN;
  c.buttons = bits;
  last_ = c;
  return c;
}

}  // namespace vdyn::wheel_input
