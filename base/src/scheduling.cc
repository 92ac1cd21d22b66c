#include "vdyn/base/scheduling.h"

#include <pthread.h>
#include <sched.h>
#include <sys/prctl.h>

#include <cstring>

namespace vdyn::base {

std::string SetUpRealtimeScheduling(int priority) {
  sched_param sp{};
  sp.sched_priority = priority;
  const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
  if (rc == 0) return "SCHED_FIFO priority " + std::to_string(priority);
  // Without real-time rights: the normal scheduler, with the smallest timer slack so a wake-up
  // is not delayed by the default 50 us slack.
  prctl(PR_SET_TIMERSLACK, 1UL, 0, 0, 0);
  return std::string("SCHED_OTHER with 1 ns timer slack (SCHED_FIFO refused: ") +
         std::strerror(rc) + ")";
}

}  // namespace vdyn::base
