// Re-simulation of a recorded session from its events: bit-exact, as fast as possible.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "vdyn/session.pb.h"
#include "world.h"

namespace vdyn {

struct ResimResult {
  bool ok = true;
  std::string error;
  // Per vehicle: the state hash after each re-simulated step, keyed by the step's index.
  std::map<std::uint32_t, std::map<std::uint64_t, std::uint64_t>> hashes;
};

// Re-simulates every vehicle of `events` (one server's events, in any order) on `world`
// from its first Spawned or Checkpoint event up to its step `end_step` (exclusive), applying each
// event at the step it names. Refuses events from another terrain (hash mismatch) or a gap in
// the event sequence.
ResimResult Resimulate(std::shared_ptr<const World> world,
                       const std::vector<pb::SessionEvent>& events,
                       const std::map<std::uint32_t, std::uint64_t>& end_step);

}  // namespace vdyn
