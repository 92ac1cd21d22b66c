// Session: the vehicles of one server on one world, advanced together step by step, with the
// rules of a networked simulation: requests validated and applied at step boundaries, input
// latched at step boundaries, an input watchdog, and an event for everything a re-simulation
// needs (spawn with the exact state, every change of applied input or parameters, every applied
// request, periodic checkpoints), stamped with the step at which it took effect.
//
// It knows nothing of DDS: the server node (server_node.h) feeds it and publishes what it says.
// Stepping - latching input, the step, the state message, events and checkpoints - and applying a
// request made ready elsewhere (Commit, with a RequestPlanner's PreparedRequest) make no heap
// allocation (tests/test_no_alloc.cc): events are plain records (below) that the server's
// publisher thread turns into messages, answers plain outcomes. Apply() does both halves of a
// request on one thread (tests, fuzzing) and allocates.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "vdyn/control.pb.h"
#include "vdyn/input.pb.h"
#include "vdyn/messages/input_checks.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/runtime/step_pool.h"
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
  // Threads that step the vehicles (the calling thread and step_threads - 1 workers of a
  // StepPool, limits::kStepThreads). Results are bit for bit the same for any count.
  int step_threads = 1;
  pb::VehicleParams default_params;  // complete; spawn requests merge over it
  // Which start of the server this is, stamped on its states, events and world (0: none given;
  // a ServerNode gives its start time, ns since the Unix epoch). A recording that holds a server
  // restarted with the same id keeps the two starts' steps and sequence numbers apart by it.
  std::uint64_t incarnation = 0;
};

// One change of the applied input: from `step` on, `input`.
struct InputChange {
  std::int64_t step = 0;
  DriverInput input;
};

// An event of the session, in the order the session emitted it (`sequence`): plain data, filled
// without allocation on the stepping thread; the server's publisher turns it into a message
// (ToMessage).
struct SessionEventRecord {
  enum class Kind {
    kInputBatch,      // changes of the applied input
    kCheckpoint,      // the exact state, input and parameters
    kSpawned,         // a vehicle starts (spawn, reset, teleport, restore, contained divergence)
    kRemoved,         // a vehicle's life ends
    kParamsChanged,   // new parameters in effect
    kControlApplied,  // an accepted request
  };
  static constexpr int kMaxBatchSamples = 32;

  Kind kind = Kind::kInputBatch;
  std::uint32_t vehicle_id = 0;
  std::int64_t step = 0;
  std::uint64_t sequence = 0;
  // kInputBatch
  int n_changes = 0;
  std::array<InputChange, kMaxBatchSamples> changes{};
  // kCheckpoint (state, input, params), kSpawned (state, params, world_name)
  State state;
  DriverInput input;
  std::shared_ptr<const pb::VehicleParams> params;  // complete, in effect
  const std::string* world_name = nullptr;          // the session's world (outlives the record)
  // kControlApplied: the request; kSpawned by a restore: the request it came from (branched_from)
  std::shared_ptr<const pb::ControlRequest> request;
};

// The message of a record (vehicle, server, step and sequence filled in).
pb::SessionEvent ToMessage(const SessionEventRecord& r, const std::string& server_id,
                           std::uint64_t terrain_hash, std::int64_t step_ns,
                           std::uint64_t incarnation = 0);

// Where Session::StepInto puts a step's states: one frame per vehicle, in id order, each filled
// with the vehicle's encoded state message (protobuf wire bytes) on the thread that stepped it -
// the state outbox (state_outbox.h), so the loop thread copies nothing.
class StateFrames {
 public:
  virtual ~StateFrames() = default;
  // Loop thread, before the parallel phase: frames for up to n states; how many it has (the
  // states beyond are refused, and counted, by Close).
  virtual std::size_t Open(std::size_t n) = 0;
  // A stepping thread, i < Open's count: frame i's buffer, filled in place.
  virtual std::span<std::uint8_t> Buffer(std::size_t i) = 0;
  // The same thread: frame i holds vehicle `key`'s state, `size` bytes (0: none - its step was
  // contained - or `too_large` for the buffer).
  virtual void Fill(std::size_t i, std::uint32_t key, std::size_t size, bool too_large) = 0;
  // Loop thread, after the step: hands the frames on; `n` as asked of Open.
  virtual void Close(std::size_t n) = 0;
};

// One vehicle of a session: its simulator, parameters, spawn pose and input state. Built off the
// stepping thread (RequestPlanner) and handed to the session whole.
struct SessionVehicle {
  std::uint32_t id = 0;
  std::unique_ptr<Simulator> sim;
  std::shared_ptr<const pb::VehicleParams> params;  // complete, in effect
  Pose2 spawn_pose;
  double spawn_speed = 0;
  pb::DriverInput live_input;  // the last live input received
  // A Restore request's exact input, applied in place of live_input until a live one arrives.
  bool input_restored = false;
  DriverInput restored_input;
  std::int64_t live_input_step = -1;  // vehicle step at which it was received (-1: none yet)
  bool safe_state = true;
  DriverInput applied;  // physics fields of the input applied last step
  bool applied_valid = false;
  pb::DriverInput applied_msg;               // the message form of what was applied
  pb::VehicleState state_msg;                // reused for every step
  StepStatus step_status = StepStatus::kOk;  // of the last step (written by a stepping thread)
  // Input changes not yet sent (an InputBatch event).
  std::array<InputChange, SessionEventRecord::kMaxBatchSamples> pending{};
  int n_pending = 0;
};
using SessionVehicles = std::map<std::uint32_t, SessionVehicle>;

// A new vehicle of a session: from `exact` when given (a restore), else at rest at `pose` (or at
// `speed` along its heading); its message buffers grown so that its first steps allocate nothing.
// Throws std::invalid_argument when the parameters do not resolve at the step, WorldError when
// it cannot start at the pose.
SessionVehicle NewVehicle(std::uint32_t id, std::shared_ptr<const World> world,
                          const SessionConfig& config,
                          std::shared_ptr<const pb::VehicleParams> params, const ValidParams& valid,
                          const State* exact, const Pose2& pose, double speed);

// A control request made ready off the stepping thread (RequestPlanner::Prepare): checked, and
// everything it needs built (a vehicle, parameters, a resting state, map nodes), so that applying
// it at a step boundary (Session::Commit) allocates nothing: it checks what only the stepping
// thread knows and swaps. What it takes out of the session is left in it (replaced_*), to be freed
// where the request came from.
struct PreparedRequest {
  enum class Op : std::uint8_t {
    kPause,
    kResume,
    kStep,
    kMove /* reset, teleport */,
    kSpawn,
    kRemove,
    kSetParams,
    kRestore
  };
  Op op = Op::kPause;
  std::shared_ptr<const pb::ControlRequest> request;
  std::uint32_t vehicle_id = 0;
  // The vehicle's parameters as the planner knew them (nullptr: no such vehicle). Commit refuses
  // a request whose vehicle is not what it was planned for.
  std::shared_ptr<const pb::VehicleParams> expected;
  std::uint32_t steps = 0;  // kStep
  bool step_input = false;  // kStep: apply request->step().input() first
  State state;              // kMove: the new state (the vehicle's step is kept)
  std::shared_ptr<const pb::VehicleParams> params;           // kSetParams: the new parameters
  std::optional<ValidParams> valid;                          // kSetParams: checked against the step
  SessionVehicles::node_type vehicle;                        // kSpawn, kRestore: the new vehicle
  std::map<std::uint32_t, std::int64_t>::node_type retired;  // kRemove: a node for its step
  // What Commit takes out of the session, freed with this request where it came from (not on
  // the stepping thread): the vehicle removed or replaced, the parameters replaced.
  SessionVehicles::node_type replaced_vehicle;
  std::shared_ptr<const pb::VehicleParams> replaced_params;
  bool applied = false;      // set by Commit: accepted (else refused)
  std::uint64_t client = 0;  // the server's: the DDS writer it came from
};

// The answer to a request, as plain data: no allocation to make one (the publisher builds the
// reply message). A refusal for a reason only the stepping thread knows carries its numbers;
// one decided elsewhere its text.
struct RequestOutcome {
  enum class Why : std::uint8_t {
    kNone,
    kText,              // `text` says why
    kExists,            // the vehicle exists already
    kFull,              // max_vehicles
    kStepBehind,        // restore: vehicle_step, restore_step
    kChanged,           // the vehicle changed between planning and applying
    kCancelledByPause,  // a step request's steps were cancelled
    kCancelledByResume,
    kClientGone,  // a step request's client left: steps_not_run (no reply is sent)
    kStopped,     // the server stopped before its steps were done
  };
  std::shared_ptr<const pb::ControlRequest> request;
  bool accepted = false;
  Why why = Why::kNone;
  std::int64_t max_vehicles = 0;   // kFull: the server's most vehicles
  std::int64_t vehicle_step = 0;   // kStepBehind: the vehicle's step (its steps only go forward)
  std::int64_t restore_step = 0;   // kStepBehind: the step of the state to restore
  std::int64_t steps_not_run = 0;  // kClientGone
  std::int64_t applied_step = -1;  // the vehicle's step then (-1: no such vehicle)
  std::int64_t sim_time_ns = 0;
  std::string text;
  // A step request's: the vehicles whose steps were discarded while its steps ran (contained:
  // no state published for them), the first kDiscardedListed of them; the rest only counted.
  struct Discarded {
    std::uint32_t vehicle_id = 0;
    std::uint32_t count = 0;
    std::int64_t first_step = 0;
    StepStatus first_status = StepStatus::kOk;
  };
  static constexpr std::size_t kDiscardedListed = 16;
  std::array<Discarded, kDiscardedListed> discarded{};
  std::uint8_t n_discarded = 0;
  std::uint32_t discarded_not_listed = 0;  // discarded steps of vehicles beyond the list
  std::uint32_t steps_without_state = 0;   // steps every vehicle's state was discarded
  void AddDiscarded(std::uint32_t vehicle_id, std::int64_t step, StepStatus status);
};

// What became of a vehicle whose step was contained (non-finite, under the ground), as the log
// and a step request's reply say it.
std::string ContainedWhy(StepStatus status);

// The reason of a refusal as a person reads it.
std::string OutcomeReason(const RequestOutcome& o, const std::string& server_id);
// The reply to send.
pb::ControlReply ToReply(const RequestOutcome& o, const std::string& server_id);

class Session {
 public:
  using EventSink = std::function<void(SessionEventRecord&&)>;
  using StateSink = std::function<void(std::uint32_t, const pb::VehicleState&)>;

  Session(std::shared_ptr<const World> world, SessionConfig config, EventSink on_event);

  // Applies a request now (call it at a step boundary) and answers it: Prepare (a planner of
  // this session's vehicles) and Commit in one, on this thread.
  [[nodiscard]] pb::ControlReply Apply(const pb::ControlRequest& request);
  // The answer to a request refused before it reached Apply.
  [[nodiscard]] pb::ControlReply Reject(const pb::ControlRequest& request,
                                        const std::string& reason);
  // Applies a prepared request at a step boundary: checks what only this thread knows (the
  // vehicle is what the plan assumed, the vehicle count, a restore's step) and swaps. No
  // allocation: events go out as plain records, the answer is plain data.
  [[nodiscard]] RequestOutcome Commit(PreparedRequest& p);
  // Spawns directly (the server's own vehicles at start). Throws std::invalid_argument.
  void Spawn(std::uint32_t vehicle_id, const Pose2& pose, double speed,
             const pb::VehicleParams& params_update);

  // Offers a live input for the next step boundary. Returns false (and why) when it is refused:
  // unknown vehicle or a value out of range. Non-finite values never get here (transport).
  [[nodiscard]] bool OfferInput(const pb::DriverInput& input, std::string* reason);

  // One step of every vehicle, in three phases: (1) serial, in id order: each vehicle's input
  // latched (its input events); (2) on the step pool, each vehicle in one thread's contiguous
  // part of the id order: its step and, with on_state, its own state message; (3) serial, in id
  // order: a non-finite step contained, on_state, input flushes and checkpoints. So events and
  // states come out in the same order and with the same content for any number of threads.
  void Step(const StateSink& on_state = {});
  // Step, with each state message also encoded on the pool (protobuf wire bytes, the costly part
  // of publishing it) straight into `frames`: vehicle i of the id order into frame i.
  void StepInto(StateFrames& frames);
  int step_threads() const { return pool_.threads(); }
  // The pool's workers get the loop's scheduling (StepPool::SetRealtimePriority).
  std::string SetStepThreadsPriority(int priority) { return pool_.SetRealtimePriority(priority); }
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
  const SessionVehicles& vehicles() const { return vehicles_; }
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
  using Vehicle = SessionVehicle;

  // Starts an event record of the vehicle (its gathered input changes go out first).
  SessionEventRecord& Begin(SessionEventRecord::Kind kind, std::uint32_t vehicle_id,
                            std::int64_t step);
  void Emit();
  void EmitSpawned(Vehicle& v, std::shared_ptr<const pb::ControlRequest> from = nullptr);
  void FlushInputs(Vehicle& v);
  // The outcome of an accepted request: the vehicle's step, and the ControlApplied event.
  RequestOutcome Accept(const std::shared_ptr<const pb::ControlRequest>& r);
  RequestOutcome Refuse(const std::shared_ptr<const pb::ControlRequest>& r,
                        RequestOutcome::Why why);
  // Commit's stages: whether the vehicle is still what the plan assumed, then one per operation.
  bool AsPlanned(const PreparedRequest& p, SessionVehicles::iterator it) const;
  RequestOutcome CommitOperation(PreparedRequest& p);
  RequestOutcome CommitPacing(const PreparedRequest& p);
  RequestOutcome CommitMove(const PreparedRequest& p, Vehicle& v);
  RequestOutcome CommitSpawn(PreparedRequest& p, bool exists);
  RequestOutcome CommitRemove(PreparedRequest& p, SessionVehicles::iterator it);
  RequestOutcome CommitSetParams(PreparedRequest& p, Vehicle& v);
  RequestOutcome CommitRestore(PreparedRequest& p, SessionVehicles::iterator it);
  void LatchInput(Vehicle& v);
  void ContainNonFinite(Vehicle& v);
  // Phase 2 of Step for the vehicles [begin, end) of order_ (on any of the pool's threads).
  enum class Fill : std::uint8_t { kNone, kMessage, kEncoded };
  void StepPart(std::size_t begin, std::size_t end, Fill fill);
  void StepPhases(const StateSink* on_state, StateFrames* frames);

  std::shared_ptr<const World> world_;
  SessionConfig config_;
  EventSink on_event_;
  SessionVehicles vehicles_;
  std::map<std::uint32_t, std::int64_t> retired_steps_;  // removed ids: the step they ended at
  bool paused_ = false;
  std::uint32_t pending_steps_ = 0;
  std::int64_t steps_ = 0;
  std::int64_t batch_steps_ = 25;  // input_batch_ns in steps
  std::uint64_t event_sequence_ = 0;
  std::uint64_t terrain_hash_ = 0;
  SessionEventRecord scratch_;  // the record being filled (reused: no allocation)
  // The vehicles in id order, the pool's partition cut from it: rebuilt (within its reserve of
  // max_vehicles) only when the set of vehicles changed.
  std::vector<Vehicle*> order_;
  bool order_stale_ = true;
  StateFrames* frames_ = nullptr;  // StepInto's, during its step
  std::size_t frames_open_ = 0;    // how many of them
  StepPool pool_;
};

// Checks a driver input's ranges (the table of limits); empty when valid, else the reason. In the
// messages layer, so that clients check their input with the server's own check.
using messages::CheckInputRanges;

}  // namespace vdyn
