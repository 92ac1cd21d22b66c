// Re-simulation of a recorded session from its events: bit-exact, as fast as possible.
//
// A VehicleReplayer replays one vehicle: its events (spawned with the exact state, input batches,
// parameter changes, removals, checkpoints) become actions at the steps they name, and the
// simulator steps between them; the state hash after every step is what a recording is checked
// against. Resimulate() runs one per vehicle. The recorder's `verify` links this library (and the
// physics) by name; no other client does.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "vdyn/physics/simulator.h"
#include "vdyn/physics/world.h"
#include "vdyn/session.pb.h"

namespace vdyn {

class VehicleReplayer {
 public:
  // `terrain_hash` is the world's (TerrainHash); a vehicle recorded on another terrain is refused.
  VehicleReplayer(std::shared_ptr<const World> world, std::uint64_t terrain_hash,
                  std::uint32_t vehicle_id);

  // Adds this vehicle's next event (events in sequence order). False, and why, for an event
  // that cannot be replayed (another vehicle, another terrain, a step that goes backwards).
  [[nodiscard]] bool Add(const pb::SessionEvent& e, std::string* error);

  // Replays from the first spawn or checkpoint up to step `end_step` (exclusive), calling
  // on_step(step, hash_after) for every step. False, and why, when it cannot go on. Called again
  // with a later end_step it goes on where it stopped (a recorder's verify streams a file this
  // way); the events at the step it stopped at are already applied.
  [[nodiscard]] bool Run(std::uint64_t end_step,
           const std::function<void(std::uint64_t, std::uint64_t)>& on_step, std::string* error);

  // The simulator, once started (nullptr before the first spawn or checkpoint, or after removal).
  const Simulator* simulator() const { return sim_.get(); }

 private:
  struct Action {
    enum class Kind { kSpawned, kCheckpoint, kInput, kParams, kRemoved } kind;
    std::uint64_t step = 0;
    State state;
    DriverInput input;
    std::shared_ptr<const ValidParams> params;
    std::int64_t step_ns = 0;
  };
  bool Apply(const Action& a, std::string* error);

  std::shared_ptr<const World> world_;
  std::uint64_t terrain_hash_;
  std::uint32_t vehicle_id_;
  std::vector<Action> actions_;
  std::size_t next_ = 0;   // the next action to apply
  bool started_ = false;
  std::unique_ptr<Simulator> sim_;
};

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
