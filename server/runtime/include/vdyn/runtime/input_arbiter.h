// Which source drives a vehicle: the strongest live source whose input is valid.
//
// vdyn/input is read with shared ownership, so the server sees every source (a primary rig, a
// backup device, a player) and decides itself: a source is live while its last *valid* sample is
// younger than the lease (OwnershipLease: 200 ms, or less than the watchdog when that is
// shorter, so a live backup drives before the vehicle would brake for want of input); among
// live sources the strongest (its writer's ownership
// strength, then the current owner on a tie) drives. A source whose samples are refused - a NaN,
// a value out of range, a malformed payload - stops refreshing its liveness and loses the vehicle
// to a valid backup within the lease; the diagnostics name it and say why (issue: a live rig
// sending bad input must not lock out the backup).
//
// Used by the server's receiver thread only (not thread-safe; Snapshot() copies for others).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "vdyn/base/time.h"
#include "vdyn/input.pb.h"

namespace vdyn {

// The lease for a server whose input watchdog is `watchdog`: the DDS liveliness lease of
// vdyn/input (200 ms), or three quarters of the watchdog when that is shorter (75 ms for the
// default 100 ms), so that a live backup takes the vehicle over before the watchdog's safe state
// would brake it, with a quarter of the watchdog to spare for a late receiver thread. Never
// under 10 ms (1 kHz samples a little late must not pass the vehicle back and forth).
base::Nanos OwnershipLease(base::Nanos watchdog);

class InputArbiter {
 public:
  explicit InputArbiter(base::Nanos lease) : lease_(lease) {}

  // A valid sample from writer `handle` (strength as its QoS declares it): true when it comes
  // from the source that drives its vehicle now, i.e. the server should apply it.
  bool Offer(const pb::DriverInput& in, std::uint64_t handle, std::int32_t strength,
             base::MonoTime now);
  // A refused sample from writer `handle` (for `vehicle_id` and from `source_id` when they could
  // be read, else 0 and empty), and why.
  void Refuse(std::uint64_t handle, std::uint32_t vehicle_id, const std::string& source_id,
              const std::string& reason, base::MonoTime now);
  // Whether a writer has been seen (its strength is known).
  bool Knows(std::uint64_t handle) const { return sources_.count(handle) != 0; }
  // Forgets writers that no longer exist.
  void Forget(const std::vector<std::uint64_t>& live_handles);

  struct Source {
    std::uint64_t handle = 0;
    std::uint32_t vehicle_id = 0;
    std::string source_id;
    std::int32_t strength = 0;
    base::MonoTime last_valid{-1};
    base::MonoTime last_refused{-1};
    std::string last_refusal;
    std::uint64_t accepted = 0;
    std::uint64_t refused = 0;
    bool driving = false;
  };
  // Every source known, as of `now` (`driving` filled in).
  std::vector<Source> Snapshot(base::MonoTime now) const;
  // The owner of a vehicle now, or 0.
  std::uint64_t Owner(std::uint32_t vehicle_id, base::MonoTime now) const;

 private:
  bool Live(const Source& s, base::MonoTime now) const;

  base::Nanos lease_;
  std::map<std::uint64_t, Source> sources_;          // by writer handle
  std::map<std::uint32_t, std::uint64_t> owner_;     // vehicle -> writer handle
};

}  // namespace vdyn
