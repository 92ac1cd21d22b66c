// The Python client's C++ side: a connection to one server on a DDS domain (world, vehicles,
// control requests, lockstep steps with their states), a driver (input with a source id and an
// ownership strength, once or at a fixed rate in the background) and a real-time subscription
// (every state of one vehicle). Built only on the client layer: no physics, no server code.
// Every wait is bounded and ends in TimeoutError naming what did not arrive.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "state_columns.h"
#include "state_source.h"
#include "vdyn/client/driver_input.h"
#include "vdyn/client/session_view.h"
#include "vdyn/control.pb.h"
#include "vdyn/transport/control_client.h"
#include "vdyn/transport/dds.h"

namespace vdyn::python {

struct ReplyInfo {
  std::string server_id;
  std::uint64_t applied_step = 0;
  std::int64_t sim_time_ns = 0;
  // A step request's: the steps the server discarded (contained), by vehicle, which published no
  // state; and each as a person reads it.
  std::map<std::uint32_t, std::uint32_t> discarded;
  std::uint32_t discarded_not_listed = 0;
  std::uint32_t steps_without_state = 0;  // of the request's steps: no vehicle's state at all
  std::vector<std::string> discarded_notes;
};

class Client {
 public:
  // Connects: waits up to `timeout_s` for a server (the one named `server_id`, or the first whose
  // world arrives) to match this client's control writer and publish its world.
  Client(std::uint32_t domain, const std::string& server_id, double timeout_s,
         const std::string& client_id);
  ~Client();

  const std::string& server_id() const { return server_id_; }
  std::uint32_t domain() const { return participant_.domain_id(); }
  double timeout_s() const { return timeout_s_; }
  // The server's world description, serialised (vdyn.pb.WorldDescription).
  std::string WorldBytes();
  // Counts the worlds received (a restarted server publishes its world again): what a cache of
  // the world compares.
  std::uint64_t WorldVersion();
  // The vehicles of the server as this client knows them: the world's at the start, those this
  // client spawned, restored or removed since, and any whose states a step delivered.
  std::vector<std::uint32_t> Vehicles();
  // A vehicle's parameters in effect, serialised (vdyn.pb.VehicleParams); waits for them.
  std::string ParamsBytes(std::uint32_t vehicle_id, double timeout_s);

  // Sends a request to this server and waits for its reply; throws TimeoutError without one in
  // time and RefusedError with the server's reason when it is rejected. `what` names it.
  ReplyInfo Request(pb::ControlRequest request, const std::string& what, double timeout_s);

  // Lockstep: `steps` steps, `input` (when given) applied first; the states of every vehicle at
  // every one of those steps. An input for a vehicle the server does not have, or one it would not
  // apply (messages::WhyInputRefused: out of range, not finite, an id too long), is refused here
  // with the reason (std::invalid_argument) before anything is stepped. Requests go in chunks the
  // server's state outbox holds whole; with an input, in chunks of at most 50 steps, each carrying
  // it (the server's input watchdog, 100 ms by default, replaces an input that is not renewed).
  // A step the server discarded (its state went non-finite, the car fell through the ground: the
  // vehicle put back at rest) has no state: it is left out, and said in `discarded` when given.
  std::map<std::uint32_t, StateTable> Step(std::uint32_t steps, const pb::DriverInput* input,
                                           double timeout_s,
                                           std::vector<std::string>* discarded = nullptr);
  // A maneuver (a CSV file as vdyn-server --batch reads it, or "demo") driven in lockstep for
  // `duration_s` (limits::kDurationS; none: to its last row) from the vehicle's step on: at each
  // step the input the maneuver gives at that step's time from the start, as the batch runner
  // applies it; steps whose inputs are equal go in one request. Every vehicle's states of those
  // steps.
  std::map<std::uint32_t, StateTable> RunManeuver(const std::string& maneuver,
                                                  std::uint32_t vehicle_id,
                                                  std::optional<double> duration_s,
                                                  const std::string& source_id, double timeout_s,
                                                  std::vector<std::string>* discarded = nullptr);
  // The newest state of a vehicle (waits up to timeout_s for a first one).
  StateTable Latest(std::uint32_t vehicle_id, double timeout_s);
  // The states this client receives, one line per reader it holds ("vehicle 2 (its partition)",
  // "every vehicle (vdyn/states)"): none until Latest() or Step() asks (Subscription objects
  // have their own).
  std::vector<std::string> StateReaders();
  // How many states of each vehicle this client's readers have taken so far (Latest() and Step()
  // take them; a Subscription counts its own): which states arrived here.
  std::map<std::uint32_t, std::uint64_t> StatesReceived();

  transport::Participant& participant() { return participant_; }

 private:
  void PollView();
  // Step()'s stages: the input checked; how many steps one request asks for; that request's
  // states taken (every vehicle's, the input's vehicle among them).
  void CheckStepInput(const pb::DriverInput& input);
  std::uint32_t ChunkSteps(std::uint32_t left, bool with_input);
  void TakeStepStates(StateSource& states, std::uint32_t chunk, const ReplyInfo& reply,
                      const pb::DriverInput* input, double timeout_s,
                      std::map<std::uint32_t, StateTable>& out);
  // Vehicles() and those whose parameters the server published, less those this client removed
  // (with mutex_ held); "its vehicles are 1, 2" for a message.
  std::set<std::uint32_t> KnownVehicles();
  static std::string VehicleList(const std::set<std::uint32_t>& ids);
  // For a wait that found nothing (with mutex_ held): "server 's' has no vehicle 9: its vehicle
  // is 1" when the vehicle is not known, else `otherwise` (the likely reason it is).
  std::string UnknownVehicleNote(std::uint32_t vehicle_id, const std::string& otherwise);
  std::string server_id_;
  double timeout_s_;
  std::mutex mutex_;
  std::mutex step_mu_;  // held by Step() throughout, never while mutex_ is
  std::mutex latest_mu_;  // held by Latest() throughout, never while mutex_ is
  transport::Participant participant_;
  transport::ControlClient control_;
  client::SessionView view_;  // world, params, diagnostics (no states)
  // The states a step asked for: every vehicle's, read from the first Step() on (a client that
  // never steps receives none; before, every client read every state from its start: 13.5 % of a
  // core and a growing history of 350 MB beside a real-time server of 128 vehicles).
  StateSource& StepStates(double timeout_s);
  // Latest(): each vehicle's states in its partition (the others' are not sent here), up to
  // kLatestPartitions vehicles; beyond, one reader of every vehicle for the rest.
  static constexpr std::size_t kLatestPartitions = 16;
  client::SessionView& LatestView(std::uint32_t vehicle_id);
  std::map<std::uint32_t, std::unique_ptr<client::SessionView>> latest_;
  std::unique_ptr<client::SessionView> latest_all_;
  std::unique_ptr<StateSource> states_;
  std::set<std::uint32_t> vehicles_;  // see Vehicles(); a step expects states of each
  std::set<std::uint32_t> removed_;   // removed by this client (and not added since)
  std::map<std::uint32_t, std::uint64_t> received_;  // StatesReceived()
  std::map<std::uint32_t, pb::VehicleState> from_steps_;  // each vehicle's newest from Step()
  std::int64_t step_ns_ = 1'000'000;
};

// Driver input for one vehicle from one source with an ownership strength.
class Driver {
 public:
  Driver(Client& client, std::uint32_t vehicle_id, const std::string& source_id,
         std::int32_t strength);
  ~Driver();
  // A vehicle id, source id or strength a server would refuse throws std::invalid_argument with
  // the reason, as does an input it would not apply (Send, Set: messages::WhyInputRefused).
  // Publishes once, now.
  void Send(const pb::DriverInput& input);
  // Publishes the current input at `rate_hz` from a thread of its own until Stop().
  void Start(double rate_hz);
  void Set(const pb::DriverInput& input);  // the input the background thread sends from now on
  void Stop();
  bool running() const { return running_.load(); }
  std::uint64_t sent();
  std::uint64_t failed() const { return failed_.load(); }
  std::uint64_t skipped_ticks() const { return skipped_.load(); }
  // Waits until the server's reader of vdyn/input has matched (input sent before may be lost).
  bool WaitForServer(double timeout_s);

 private:
  void CheckInput(const pb::DriverInput& input) const;
  std::mutex mutex_;
  std::uint32_t vehicle_id_;
  client::InputPublisher publisher_;
  pb::DriverInput current_, sending_;
  std::atomic<bool> running_{false};
  std::atomic<std::uint64_t> failed_{0}, skipped_{0};
  // The sending thread waits for its next tick on this, so that Stop() ends the wait at once
  // (a sleep of the whole period held stop() for it: for ever at a rate of 1e-6 Hz).
  std::mutex stop_mu_;
  std::condition_variable stop_cv_;
  std::thread thread_;
};

// Every state of one vehicle as it arrives, taken by a thread of its own into a bounded queue.
class Subscription {
 public:
  Subscription(Client& client, std::uint32_t vehicle_id, std::size_t capacity);
  ~Subscription();
  // The next state (one row); TimeoutError when none arrives within timeout_s.
  StateTable Next(double timeout_s);
  // Every state queued now (possibly none).
  StateTable TakeAll();
  void Close();
  std::uint64_t received() const { return received_.load(); }
  // States lost: the queue overflowed (the Python side fell behind by `capacity` states), DDS
  // overwrote them before they were taken, or steps missing in the sequence.
  std::uint64_t overflowed() const { return overflowed_.load(); }
  std::uint64_t missing_steps() const { return missing_.load(); }
  // Times the server restarted under this subscription (another start's states began: its steps
  // count from 0 again, and no steps count as missing across it).
  std::uint64_t restarts() const { return restarts_.load(); }
  // States DDS reports it dropped for this reader (its history overwritten before a take).
  std::uint64_t dds_lost();
  std::size_t queued();

 private:
  void Run();
  std::uint32_t vehicle_id_;
  std::size_t capacity_;
  std::string server_id_;  // the client's: another server's states of the vehicle are not its
  StateSource source_;
  std::mutex mutex_;
  std::condition_variable ready_;
  StateTable queue_;  // rows [head_, end)
  std::size_t head_ = 0;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> received_{0}, overflowed_{0}, missing_{0}, restarts_{0};
  std::optional<std::uint64_t> last_step_;
  std::optional<std::uint64_t> incarnation_;  // the server start whose states come now
  std::mutex close_mu_;
  std::thread thread_;
};

}  // namespace vdyn::python
