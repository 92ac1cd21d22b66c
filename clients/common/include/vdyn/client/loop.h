// A fixed-rate loop for clients (input at 1 kHz, force feedback at 500 Hz, a player's clock):
// absolute deadlines on the monotonic clock; a tick that is late by more than a period skips the
// missed ticks instead of bursting to catch up (a client sends the present, not the past).
#pragma once

#include <cstdint>

#include "vdyn/base/time.h"

namespace vdyn::client {

class FixedRateLoop {
 public:
  // period > 0.
  explicit FixedRateLoop(base::Nanos period, base::MonoTime start = base::MonotonicNow());

  struct Tick {
    base::MonoTime deadline;  // when this tick was due
    base::MonoTime now;       // when it started
    std::uint64_t index = 0;  // ticks since the start, skipped ones included
    std::uint64_t skipped = 0;  // ticks skipped before this one (this machine was busy)
  };
  // Sleeps until the next deadline and returns it.
  Tick Wait();

  base::Nanos period() const { return period_; }
  std::uint64_t skipped_total() const { return skipped_total_; }

 private:
  base::Nanos period_;
  base::MonoTime next_;
  std::uint64_t index_ = 0;
  std::uint64_t skipped_total_ = 0;
};

}  // namespace vdyn::client
