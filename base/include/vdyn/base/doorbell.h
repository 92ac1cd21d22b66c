// A doorbell between threads: Ring() never blocks and never takes a lock (a futex wake, and only
// when someone waits); Wait() sleeps until a ring after the token it was given, or a timeout.
// The 1 kHz thread rings its publisher; a receiver rings a lockstep loop.
//
//   const auto token = bell.Token();
//   if (nothing to do) bell.Wait(token, timeout);   // returns at once if rung since Token()
#pragma once

#include <atomic>
#include <cstdint>

#include "vdyn/base/time.h"

namespace vdyn::base {

class Doorbell {
 public:
  std::uint32_t Token() const { return seq_.load(std::memory_order_seq_cst); }
  void Ring();
  // Returns when the bell has rung since `token` was taken, or after `timeout`.
  void Wait(std::uint32_t token, Nanos timeout);

 private:
  std::atomic<std::uint32_t> seq_{0};
  std::atomic<int> waiters_{0};
};

}  // namespace vdyn::base
