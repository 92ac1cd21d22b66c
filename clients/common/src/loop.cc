#include "vdyn/client/loop.h"

#include <stdexcept>

namespace vdyn::client {

FixedRateLoop::FixedRateLoop(base::Nanos period, base::MonoTime start)
    : period_(period), next_(start) {
  if (period.ns <= 0) throw std::invalid_argument("a loop's period must be positive");
}

FixedRateLoop::Tick FixedRateLoop::Wait() {
  base::SleepUntil(next_);
  Tick t;
  t.now = base::MonotonicNow();
  t.deadline = next_;
  t.index = index_;
  // Late by more than a period: skip to the latest deadline that has passed.
  const std::int64_t behind = (t.now - next_).ns / period_.ns;
  if (behind > 0) {
    t.skipped = static_cast<std::uint64_t>(behind);
    skipped_total_ += t.skipped;
    index_ += t.skipped;
    next_ = next_ + base::Nanos{behind * period_.ns};
    t.deadline = next_;
    t.index = index_;
  }
  next_ = next_ + period_;
  ++index_;
  return t;
}

}  // namespace vdyn::client
