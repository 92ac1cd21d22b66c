// Motion: each frame shows every vehicle as it was at one instant, the frame's display time less
// a small fixed presentation delay, interpolated between the two received states around it.
//
// States are published at 1 kHz and frames come at 60-90 Hz (the viewer takes the newest state of
// each vehicle per frame), so the instant a frame shows falls between two received states. The
// timeline is the publisher's: the DDS source stamp of each state (the server's or the player's
// wall clock when it wrote it), mapped onto this machine's clock by the smallest transit seen
// (which also absorbs an offset between the two machines' clocks). A frame due on the screen at
// wall time D shows source time D - offset - delay; the delay (30 ms by default) keeps a newer
// state on the far side of that instant while frames take up to a few tens of milliseconds and
// states arrive with jitter. When no newer state has arrived (a paused server, a stalled
// network), the newest is shown as it is; nothing is extrapolated.
//
//   source time ──a────────●────────b──────────── newest ──> (states as received)
//                          │ shown = D - offset - delay
//                          u = (shown - a) / (b - a)
//
// Between a and b: positions, forces, speeds and every other continuous number linearly, the
// orientation by slerp, angles about the vertical (yaw) the short way round; discrete values
// (step, gear, contact, ids, hashes) are a's until b is reached. States that do not follow each
// other (a restore, a reset or teleport, a server restarted: the step and the simulation clock
// disagree or the vehicle moved further than its speed allows) are never blended: a until b.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <string>

#include "vdyn/state.pb.h"

namespace vdyn::viewer {

inline constexpr std::int64_t kDefaultPresentationDelayNs = 30'000'000;  // 30 ms

// `out` = a blended with b at u in [0, 1] (0: a, 1: b), as described above. a and b must hold the
// same vehicle with four wheels each (CheckState).
void InterpolateState(const pb::VehicleState& a, const pb::VehicleState& b, double u,
                      pb::VehicleState& out);

// True when b follows a in one continuous drive: same server, later step, the simulation clock
// advanced by exactly the steps between them, and no jump further than the vehicle's speed allows.
bool Continuous(const pb::VehicleState& a, const pb::VehicleState& b);

// The offset between a publisher's clock and this machine's: the smallest (arrival - source
// stamp) seen, allowed to rise slowly (1 ms per second) so a clock that drifts or a transit that
// was once unusually short is followed.
class ClockOffset {
 public:
  void Observe(std::int64_t source_ns, std::int64_t arrived_wall_ns);
  std::int64_t offset_ns() const { return offset_ns_; }
  bool known() const { return known_; }

 private:
  bool known_ = false;
  std::int64_t offset_ns_ = 0;
  std::int64_t last_arrival_ns_ = 0;
};

// A vehicle's states as received (at most kCapacity, oldest dropped), for drawing it at an instant.
class StateHistory {
 public:
  static constexpr std::size_t kCapacity = 64;

  // Adds a state received at `arrived_wall_ns` with its source stamp. A repeat of the newest
  // (same step and server) is ignored; a state that does not follow the newest and is older by
  // step or source stamp (a seek back, a restarted server) starts the history afresh.
  void Add(const pb::VehicleState& s, std::int64_t source_ns, std::int64_t arrived_wall_ns);

  struct Sample {
    const pb::VehicleState* a = nullptr;  // at or before the instant (the newest when held)
    const pb::VehicleState* b = nullptr;  // after it; null when a is shown as it is
    double u = 0;                         // 0..1 from a to b
    std::int64_t source_ns = 0;           // the instant shown, publisher's clock
    std::int64_t a_source_ns = 0;         // a's source stamp
  };
  // The states around source time `t_ns` (the oldest when t is before it, the newest when after).
  Sample At(std::int64_t t_ns) const;

  bool empty() const { return entries_.empty(); }
  const pb::VehicleState& newest() const { return entries_.back().state; }
  std::int64_t newest_source_ns() const { return entries_.back().source_ns; }
  std::size_t size() const { return entries_.size(); }

 private:
  struct Entry {
    pb::VehicleState state;
    std::int64_t source_ns = 0;
  };
  std::deque<Entry> entries_;
};

}  // namespace vdyn::viewer
