// A bounded wait, written once: a deadline on the monotonic clock that a timeout of any size can
// name (one too long to count in nanoseconds, ~292 years, never passes instead of wrapping round
// into the past), and the loop every client writes around it: look, and while what it waits for
// has not come and time is left, block on its reader for a slice of what is left.
//
//   const base::Deadline deadline = base::Deadline::AfterSeconds(timeout_s);
//   const bool got = base::PollUntil(deadline, base::Milliseconds(20),
//                                    [&] { view.Poll(); return view.vehicle(id) != nullptr; },
//                                    [&](base::Nanos slice) { (void)view.Wait(slice); });
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <limits>

#include "vdyn/base/time.h"

namespace vdyn::base {

class Deadline {
 public:
  // `d` from now (a negative d: now).
  static Deadline After(Nanos d, MonoTime now = MonotonicNow());
  // `seconds` from now; +infinity and times beyond the clock's range never pass. NaN and negative
  // times are the caller's to refuse (they are taken as 0).
  static Deadline AfterSeconds(double seconds, MonoTime now = MonotonicNow());
  static Deadline Never() { return Deadline(MonoTime{std::numeric_limits<std::int64_t>::max()}); }

  bool never() const { return at_.ns == std::numeric_limits<std::int64_t>::max(); }
  bool Passed(MonoTime now = MonotonicNow()) const { return !never() && now >= at_; }
  // What is left of it, never negative (for a deadline that never passes: the longest Nanos).
  Nanos Left(MonoTime now = MonotonicNow()) const;
  MonoTime at() const { return at_; }

 private:
  explicit Deadline(MonoTime at) : at_(at) {}
  MonoTime at_;
};

// As a std::chrono duration, for the readers' Wait(std::chrono::nanoseconds).
inline std::chrono::nanoseconds Chrono(Nanos d) {
  return std::chrono::nanoseconds(d.ns);
}
// And back, for a timeout given as a std::chrono duration.
inline Nanos FromChrono(std::chrono::nanoseconds d) {
  return Nanos{d.count()};
}

// What a thread runs between the waits of PollUntil, when set: the Python module checks for
// Ctrl-C there (and throws to end the wait). None by default, for each thread.
using WaitHook = void (*)();
inline WaitHook& ThreadWaitHook() {
  thread_local WaitHook hook = nullptr;
  return hook;
}

// Calls done() until it returns true or the deadline passes; between calls, wait(slice) blocks for
// at most `slice` or what is left of the deadline, whichever is shorter (a reader's or waitset's
// Wait, which returns early when data arrives). done() is called at least once, and once more
// after the last wait, so what arrived in the last slice counts. True when done() returned true.
template <class Done, class Wait>
bool PollUntil(const Deadline& deadline, Nanos slice, Done&& done, Wait&& wait) {
  for (;;) {
    if (done()) return true;
    const MonoTime now = MonotonicNow();
    if (deadline.Passed(now)) return false;
    if (const WaitHook hook = ThreadWaitHook()) hook();
    wait(std::min(slice, deadline.Left(now)));
  }
}

}  // namespace vdyn::base
