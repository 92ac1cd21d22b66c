// Real-time scheduling for a program's periodic thread (the server's 1 kHz loop, vdyn-input's
// rig loop): SCHED_FIFO where the system permits it, else the normal scheduler with the finest
// timer slack; and the line that says which, as every program prints it.
#pragma once

#include <string>

namespace vdyn::base {

// Asks for SCHED_FIFO at `priority` for the calling thread; falls back to SCHED_OTHER with a
// 1 ns timer slack. Returns a line saying which: "SCHED_FIFO priority 50", or "SCHED_OTHER with
// 1 ns timer slack (SCHED_FIFO refused: Operation not permitted)".
std::string SetUpRealtimeScheduling(int priority);

}  // namespace vdyn::base
