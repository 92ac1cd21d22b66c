#include "vdyn/messages/input_checks.h"

#include "vdyn/base/limits.h"
#include "vdyn/messages/checks.h"

namespace vdyn::messages {

std::string CheckInputRanges(const pb::DriverInput& in) {
  if (!pb::SteerMode_IsValid(in.steer_mode())) {
    return "steer_mode " + std::to_string(in.steer_mode()) + " is not a steer mode";
  }
  const limits::Range& steer =
      in.steer_mode() == pb::STEER_HAND_WHEEL ? limits::kHandWheel : limits::kSteer;
  for (const std::string& why :
       {limits::Check(steer, in.steer()), limits::Check(limits::kThrottle, in.throttle()),
        limits::Check(limits::kBrake, in.brake()),
        limits::Check(limits::kCruiseSetKmh, in.cruise_set_kmh()),
        limits::Check(limits::kClutch, in.clutch()),
        limits::Check(limits::kHandbrake, in.handbrake()),
        limits::Check(limits::kGear, in.gear())}) {
    if (!why.empty()) return why;
  }
  return {};
}

std::string WhyInputRefused(const pb::DriverInput& in) {
  // The ranges first: their reasons name the quantity and its limits (a NaN steering angle is
  // "steer (front road-wheel angle, rad) must be a finite number, got nan").
  if (std::string why = CheckInputRanges(in); !why.empty()) return why;
  const Finding f = CheckMessage(in);
  switch (f.problem) {
    case Problem::kNone:
      return {};
    case Problem::kNonFinite:
      return f.field + " is not a finite number";
    case Problem::kStringTooLong:
      break;
  }
  const std::string& text = f.field == "source_id" ? in.source_id() : std::string();
  return f.field + (text.empty() ? "" : " is " + std::to_string(text.size()) + " bytes long;") +
         " a server takes at most " + std::to_string(MaxStringBytes(f.field)) + " bytes";
}

}  // namespace vdyn::messages
