// What a server checks in a driver input before it applies one, in one place: the server's
// receiver and lockstep steps refuse with it, and clients (the Python package) check with it
// before they send, so an input the server would not apply is refused where it is made, with the
// server's reason, instead of being dropped on arrival while the vehicle keeps its old input.
#pragma once

#include <string>

#include "vdyn/input.pb.h"

namespace vdyn::messages {

// The input's numbers against the table of limits (base/limits.h) and its steer mode; empty when
// valid, else the reason: "throttle must be in [-1, 1], got 2".
std::string CheckInputRanges(const pb::DriverInput& input);

// Everything a server refuses a driver input for: a number that is not finite, an id longer than
// the receivers take (CheckMessage), and CheckInputRanges. Empty when a server takes it, else the
// reason: "source_id is 100 bytes long; a server takes at most 64".
std::string WhyInputRefused(const pb::DriverInput& input);

}  // namespace vdyn::messages
