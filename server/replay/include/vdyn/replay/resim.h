// Re-simulation of a recorded session from its events: bit-exact, as fast as possible.
//
// A VehicleReplayer replays one vehicle: its events (spawned with the exact state, input batches,
// parameter changes, removals, checkpoints) become actions at the steps they name, and the
// simulator steps between them; the state hash after every step is what a recording is checked
// against. Resimulate() runs one per vehicle.
//
// The interface speaks messages: a recorded world description in, state messages and exact states
// out. The simulator stays inside, so a user (the recorder's `verify` and `takeover`, the tests)
// needs neither the physics nor the bridge to compare a recording with its re-simulation.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "vdyn/session.pb.h"
#include "vdyn/state.pb.h"
#include "vdyn/world.pb.h"

namespace vdyn {

struct World;

// A recorded world, rebuilt for replay, and its terrain hash (what events name).
struct ReplayWorld {
  std::shared_ptr<const World> world;
  std::uint64_t terrain_hash = 0;
};

// Rebuilds the world a server described (vdyn/world). Throws std::exception with the reason when
// the description cannot be rebuilt.
ReplayWorld ReplayWorldFrom(const pb::WorldDescription& description);

class VehicleReplayer {
 public:
  // `terrain_hash` is the world's (TerrainHash); a vehicle recorded on another terrain is refused.
  VehicleReplayer(std::shared_ptr<const World> world, std::uint64_t terrain_hash,
                  std::uint32_t vehicle_id);
  explicit VehicleReplayer(const ReplayWorld& world, std::uint32_t vehicle_id)
      : VehicleReplayer(world.world, world.terrain_hash, vehicle_id) {}
  ~VehicleReplayer();
  VehicleReplayer(const VehicleReplayer&) = delete;
  VehicleReplayer& operator=(const VehicleReplayer&) = delete;

  // Adds this vehicle's next event (events in sequence order). False, and why, for an event
  // that cannot be replayed (another vehicle, another terrain, a step that goes backwards).
  [[nodiscard]] bool Add(const pb::SessionEvent& e, std::string* error);

  // Replays from the first spawn or checkpoint up to step `end_step` (exclusive), calling
  // on_step(step, hash_after) for every step. False, and why, when it cannot go on. Called again
  // with a later end_step it goes on where it stopped (a recorder's verify streams a file this
  // way); the events at the step it stopped at are already applied.
  [[nodiscard]] bool Run(std::uint64_t end_step,
                         const std::function<void(std::uint64_t, std::uint64_t)>& on_step,
                         std::string* error);

  // The index of the step the replay last ran (its state message's step); nullopt before the
  // first spawn or checkpoint, or after a removal.
  std::optional<std::uint64_t> last_step() const;

  // The state message of the step the replay last ran, made as the server makes it; `recorded`
  // (the recorded message of that step) lends what is not physics: server id, time, the input's
  // source, the watchdog flag, the server start. nullopt when nothing runs (see last_step()).
  std::optional<pb::VehicleState> StateMessage(const pb::VehicleState& recorded) const;

  // The exact state at the boundary before step `step` and the input in force there, when the
  // replay stands at that boundary (Run(step) returned); nullopt otherwise.
  struct Exact {
    pb::ExactState state;
    pb::InputSample input;
  };
  std::optional<Exact> ExactAt(std::uint64_t step) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
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
