// Session: the vehicles of one server on one world, advanced together step by step, with the
// rules of a networked simulation: requests validated and applied at step boundaries, input
// latched at step boundaries, an input watchdog, and an event for everything a re-simulation
// needs (spawn with the exact state, every change of applied input or parameters, every applied
// request, periodic checkpoints), stamped with the step at which it took effect.
//
// It knows nothing of DDS: the server node (server_node.h) feeds it and publishes what it says.
// Stepping - latching input, the step, the state message, input events and checkpoints - makes
// no heap allocation (tests/test_no_alloc.cc): the frequent events are plain records (below) that
// the server's publisher thread turns into messages. Applying a request may allocate.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "vdyn/control.pb.h"
#include "vdyn/input.pb.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/session.pb.h"
#include "vdyn/state.pb.h"
#include "vdyn/vehicle_params.pb.h"

namespace vdyn {

struct SessionConfig {
  std::string server_id = "vdyn";
  std::int64_t step_ns = 1'000'000;
  // No live input for longer than this (simulated time): the vehicle goes to the safe state.
  double watchdog_s = 0.1;
  double safe_brake = 0.3;  // controlled braking in the safe state, [0, 1]
  std::int64_t checkpoint_every_steps = 1000;
  // Input changes are gathered for this long before they go out as one event (at most
  // kMaxBatchSamples per event): an analog wheel changing every step costs ~40 events a second.
  std::int64_t input_batch_ns = 25'000'000;
  std::size_t max_vehicles = 64;  // spawn requests beyond are refused
  pb::VehicleParams default_params;  // complete; spawn requests merge over it
};

// One change of the applied input: from `step` on, `input`.
struct InputChange {
  std::int64_t step = 0;
  DriverInput input;
};

// An event of the session, in the order the session emitted it (`sequence`). The frequent kinds
// (input batches, checkpoints) are plain data, filled without allocation; the rare ones (spawn,
// parameter change, applied request, removal) come as a finished message.
struct SessionEventRecord {
  enum class Kind { kInputBatch, kCheckpoint, kMessage };
  static constexpr int kMaxBatchSamples = 32;

  Kind kind = Kind::kMessage;
  std::uint32_t vehicle_id = 0;
  std::int64_t step = 0;
  std::uint64_t sequence = 0;
  // kInputBatch
  int n_changes = 0;
  std::array<InputChange, kMaxBatchSamples> changes{};
  // kCheckpoint
  State state;
  DriverInput input;
  std::shared_ptr<const pb::VehicleParams> params;  // complete, in effect
  // kMessage
  std::unique_ptr<pb::SessionEvent> message;
};

// The message of a record (vehicle, server, step and sequence filled in).
pb::SessionEvent ToMessage(const SessionEventRecord& r, const std::string& server_id,
                           std::uint64_t terrain_hash, std::int64_t step_ns);

class Session {
 public:
  using EventSink = std::function<void(SessionEventRecord&&)>;
  using StateSink = std::function<void(std::uint32_t, const pb::VehicleState&)>;

  Session(std::shared_ptr<const World> world, SessionConfig config, EventSink on_event);

  // Applies a request now (call it at a step boundary) and answers it.
  pb::ControlReply Apply(const pb::ControlRequest& request);
  // The answer to a request refused before it reached Apply.
  pb::ControlReply Reject(const pb::ControlRequest& request, const std::string& reason) {
    return Reply(request, false, reason);
  }
  // Spawns directly (the server's own vehicles at start). Throws std::invalid_argument.
  void Spawn(std::uint32_t vehicle_id, const Pose2& pose, double speed,
             const pb::VehicleParams& params_update);

  // Offers a live input for the next step boundary. Returns false (and why) when it is refused:
  // unknown vehicle or a value out of range. Non-finite values never get here (transport).
  bool OfferInput(const pb::DriverInput& input, std::string* reason);

  // One step of every vehicle; calls on_state for each vehicle after its step.
  void Step(const StateSink& on_state = {});
  // Sends the input changes still gathered (at shutdown, before a recorder is told to stop).
  void FlushEvents();
  // Tests only: sets a vehicle's state as it is (no checks), announced like a teleport.
  void SetStateForTesting(std::uint32_t id, const State& s);

  bool paused() const { return paused_; }
  std::int64_t steps() const { return steps_; }  // steps taken by the session
  std::int64_t step_ns() const { return config_.step_ns; }
  const SessionConfig& config() const { return config_; }
  const World& world() const { return *world_; }
  std::uint64_t terrain_hash() const { return terrain_hash_; }
  std::size_t vehicle_count() const { return vehicles_.size(); }
  bool HasVehicle(std::uint32_t id) const { return vehicles_.count(id) != 0; }
  const Simulator& simulator(std::uint32_t id) const { return *vehicles_.at(id).sim; }
  const pb::VehicleParams& params(std::uint32_t id) const { return *vehicles_.at(id).params; }
  // Watchdog view for diagnostics.
  bool in_safe_state(std::uint32_t id) const { return vehicles_.at(id).safe_state; }
  double input_age_s(std::uint32_t id) const;
  const std::string& input_source(std::uint32_t id) const {
    return vehicles_.at(id).live_input.source_id();
  }
  std::vector<std::uint32_t> vehicle_ids() const;
  // Calls fn(id) for each vehicle, in id order, without allocating.
  template <class F>
  void ForEachVehicle(F&& fn) const {
    for (const auto& [id, v] : vehicles_) fn(id);
  }
  // Steps still owed to lockstep "step N" requests (the session stays paused otherwise).
  std::uint32_t pending_steps() const { return pending_steps_; }
  void ConsumePendingStep() {
    if (pending_steps_ > 0) --pending_steps_;
  }
  // Drops `n` of the pending steps (their client is gone).
  void CancelPendingSteps(std::uint32_t n) { pending_steps_ -= std::min(n, pending_steps_); }

 private:
  struct Vehicle {
    std::uint32_t id = 0;
    std::unique_ptr<Simulator> sim;
    std::shared_ptr<const pb::VehicleParams> params;  // complete, in effect
    Pose2 spawn_pose;
    double spawn_speed = 0;
    pb::DriverInput live_input;        // the last live input received
    // A Restore request's exact input, applied in place of live_input until a live one arrives.
    bool input_restored = false;
    DriverInput restored_input;
    std::int64_t live_input_step = -1;  // vehicle step at which it was received (-1: none yet)
    bool safe_state = true;
    DriverInput applied;               // physics fields of the input applied last step
    bool applied_valid = false;
    pb::DriverInput applied_msg;       // the message form of what was applied
    pb::VehicleState state_msg;        // reused for every step
    // Input changes not yet sent (an InputBatch event).
    std::array<InputChange, SessionEventRecord::kMaxBatchSamples> pending{};
    int n_pending = 0;
  };

  void EmitMessage(std::uint32_t vehicle_id, std::int64_t step,
                   std::unique_ptr<pb::SessionEvent> e);
  void EmitSpawned(Vehicle& v, const std::string& branched_from = {});
  pb::ControlReply Restore(const pb::ControlRequest& r);
  void FlushInputs(Vehicle& v);
  pb::ControlReply Reply(const pb::ControlRequest& r, bool accepted, const std::string& reason);
  void LatchInput(Vehicle& v);

  std::shared_ptr<const World> world_;
  SessionConfig config_;
  EventSink on_event_;
  std::map<std::uint32_t, Vehicle> vehicles_;
  std::map<std::uint32_t, std::int64_t> retired_steps_;  // removed ids: the step they ended at
  bool paused_ = false;
  std::uint32_t pending_steps_ = 0;
  std::int64_t steps_ = 0;
  std::int64_t batch_steps_ = 25;  // input_batch_ns in steps
  std::uint64_t event_sequence_ = 0;
  std::uint64_t terrain_hash_ = 0;
  SessionEventRecord scratch_;  // the record being filled (reused: no allocation)
};

// Checks a driver input's ranges (the table of limits); empty when valid, else the reason.
std::string CheckInputRanges(const pb::DriverInput& input);

}  // namespace vdyn
