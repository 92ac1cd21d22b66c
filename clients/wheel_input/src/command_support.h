// What vdyn-input's commands and the rig loop share (private to the library): the loop's
// scheduling and period.
#pragma once

#include <string>

#include "vdyn/base/time.h"
#include "vdyn/wheel_input/commands.h"

namespace vdyn::wheel_input {

// Real-time scheduling for the calling (loop) thread where the system permits it; the line that
// says which, as vdyn-server prints it.
std::string SetUpLoopScheduling(const CommonOptions& c);

// One period of a loop at `hz` (whole nanoseconds, rounded down).
base::Nanos LoopPeriod(double hz);

}  // namespace vdyn::wheel_input
