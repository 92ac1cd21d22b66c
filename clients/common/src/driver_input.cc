#include "vdyn/client/driver_input.h"

#include <cmath>

#include "vdyn/base/limits.h"
#include "vdyn/base/time.h"

namespace vdyn::client {

void FillFromManeuver(const ManeuverInput& in, pb::DriverInput& out) {
  out.set_steer(in.steer);
  out.set_throttle(in.throttle);
  out.set_brake(in.brake);
  out.set_cruise_on(in.cruise_on);
  out.set_cruise_set_kmh(in.cruise_speed * 3.6);
  ClampToLimits(out);
}

int ClampToLimits(pb::DriverInput& in) {
  int changed = 0;
  auto fix = [&changed](double v, const limits::Range& r, auto set) {
    const double c = limits::Clamp(r, v, 0.0);
    if (!(c == v)) {
      ++changed;
      set(c);
    }
  };
  if (!pb::SteerMode_IsValid(in.steer_mode())) {
    ++changed;
    in.set_steer_mode(pb::STEER_ROAD_WHEEL);
    in.set_steer(0.0);
  }
  const limits::Range& steer =
      in.steer_mode() == pb::STEER_HAND_WHEEL ? limits::kHandWheel : limits::kSteer;
  fix(in.steer(), steer, [&](double v) { in.set_steer(v); });
  fix(in.throttle(), limits::kThrottle, [&](double v) { in.set_throttle(v); });
  fix(in.brake(), limits::kBrake, [&](double v) { in.set_brake(v); });
  fix(in.cruise_set_kmh(), limits::kCruiseSetKmh, [&](double v) { in.set_cruise_set_kmh(v); });
  fix(in.clutch(), limits::kClutch, [&](double v) { in.set_clutch(v); });
  fix(in.handbrake(), limits::kHandbrake, [&](double v) { in.set_handbrake(v); });
  fix(static_cast<double>(in.gear()), limits::kGear,
      [&](double v) { in.set_gear(static_cast<std::int32_t>(v)); });
  return changed;
}

InputPublisher::InputPublisher(transport::Participant& participant, std::uint32_t vehicle_id,
                               std::string source_id, std::int32_t strength)
    : writer_(participant, transport::TopicId::kInput, strength),
      vehicle_id_(vehicle_id),
      source_id_(std::move(source_id)) {}

bool InputPublisher::Publish(pb::DriverInput& msg) {
  return Publish(msg, base::MonotonicNow());
}

bool InputPublisher::Publish(pb::DriverInput& msg, base::MonoTime sampled) {
  msg.set_vehicle_id(vehicle_id_);
  msg.set_source_id(source_id_);
  msg.set_sequence(sequence_++);
  msg.set_stamp_ns(sampled.ns);
  return writer_.Write(vehicle_id_, msg);
}

}  // namespace vdyn::client
