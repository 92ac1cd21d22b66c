// Session: the vehicles of one server on one world, advanced together step by step, with the
// rules of a networked simulation: requests validated and applied at step boundaries, input
// latched at step boundaries, an input watchdog, and an event for everything a re-simulation
// needs (spawn with the exact state, every change of applied input or parameters, every applied
// request, periodic checkpoints), stamped with the step at which it took effect.
//
// It knows nothing of DDS: the server node (server_node.h) feeds it and publishes what it says.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "simulator.h"
#include "vdyn/control.pb.h"
#include "vdyn/input.pb.h"
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
  std::size_t max_vehicles = 64;  // spawn requests beyond are refused
  pb::VehicleParams default_params;  // complete; spawn requests merge over it
};

class Session {
 public:
  using EventSink = std::function<void(const pb::SessionEvent&)>;

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
  void Step(const std::function<void(std::uint32_t, const pb::VehicleState&)>& on_state = {});

  bool paused() const { return paused_; }
  std::int64_t steps() const { return steps_; }  // steps taken by the session
  std::int64_t step_ns() const { return config_.step_ns; }
  const SessionConfig& config() const { return config_; }
  const World& world() const { return *world_; }
  std::size_t vehicle_count() const { return vehicles_.size(); }
  bool HasVehicle(std::uint32_t id) const { return vehicles_.count(id) != 0; }
  const Simulator& simulator(std::uint32_t id) const { return *vehicles_.at(id).sim; }
  const pb::VehicleParams& params(std::uint32_t id) const { return vehicles_.at(id).params; }
  // Watchdog view for diagnostics.
  bool in_safe_state(std::uint32_t id) const { return vehicles_.at(id).safe_state; }
  double input_age_s(std::uint32_t id) const;
  const std::string& input_source(std::uint32_t id) const {
    return vehicles_.at(id).live_input.source_id();
  }
  std::vector<std::uint32_t> vehicle_ids() const;
  // Steps still owed to lockstep "step N" requests (the session stays paused otherwise).
  std::uint32_t pending_steps() const { return pending_steps_; }
  void ConsumePendingStep() {
    if (pending_steps_ > 0) --pending_steps_;
  }

 private:
  struct Vehicle {
    std::uint32_t id = 0;
    std::unique_ptr<Simulator> sim;
    pb::VehicleParams params;  // complete, in effect
    Pose2 spawn_pose;
    double spawn_speed = 0;
    pb::DriverInput live_input;        // the last live input received
    std::int64_t live_input_step = -1;  // vehicle step at which it was received (-1: none yet)
    bool safe_state = true;
    DriverInput applied;               // physics fields of the input applied last step
    bool applied_valid = false;
    pb::DriverInput applied_msg;       // the message form of what was applied
    pb::VehicleState state_msg;        // reused for every step
  };

  void Emit(std::uint32_t vehicle_id, std::int64_t step, pb::SessionEvent& e);
  void EmitSpawned(Vehicle& v);
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
  std::uint64_t event_sequence_ = 0;
  std::uint64_t terrain_hash_ = 0;
};

// Checks a driver input's ranges; empty when valid, else the reason.
std::string CheckInputRanges(const pb::DriverInput& input);

}  // namespace vdyn
