#include "vdyn/runtime/session.h"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "vdyn/base/limits.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/bridge/params.h"
#include "vdyn/messages/control_reply.h"
#include "vdyn/runtime/request_planner.h"

namespace vdyn {
namespace {

bool SamePhysics(const DriverInput& a, const DriverInput& b) {
  return a.steer == b.steer && a.throttle == b.throttle && a.brake == b.brake &&
         a.cruise_on == b.cruise_on && a.cruise_speed == b.cruise_speed &&
         a.steer_mode == b.steer_mode && a.clutch == b.clutch && a.handbrake == b.handbrake &&
         a.gear == b.gear;
}

}  // namespace

pb::SessionEvent ToMessage(const SessionEventRecord& r, const std::string& server_id,
                           std::uint64_t terrain_hash, std::int64_t step_ns,
                           std::uint64_t incarnation) {
  using Kind = SessionEventRecord::Kind;
  pb::SessionEvent e;
  e.set_vehicle_id(r.vehicle_id);
  e.set_server_id(server_id);
  e.set_incarnation(incarnation);
  e.set_step(static_cast<std::uint64_t>(r.step));
  e.set_sequence(r.sequence);
  switch (r.kind) {
    case Kind::kInputBatch: {
      auto* batch = e.mutable_input_batch();
      for (int i = 0; i < r.n_changes; ++i) {
        ToInputSample(r.changes[i].input, r.changes[i].step, *batch->add_samples());
      }
      break;
    }
    case Kind::kCheckpoint: {
      auto* c = e.mutable_checkpoint();
      *c->mutable_state() = ToExactState(r.state);
      if (r.params) *c->mutable_params() = *r.params;
      ToInputSample(r.input, r.step, *c->mutable_input());
      c->set_terrain_hash(terrain_hash);
      c->set_step_ns(step_ns);
      break;
    }
    case Kind::kSpawned: {
      auto* s = e.mutable_spawned();
      if (r.request && r.request->has_restore()) {
        s->set_branched_from(r.request->restore().branched_from());
      }
      *s->mutable_state() = ToExactState(r.state);
      if (r.params) *s->mutable_params() = *r.params;
      if (r.world_name != nullptr) s->set_world_name(*r.world_name);
      s->set_terrain_hash(terrain_hash);
      s->set_step_ns(step_ns);
      break;
    }
    case Kind::kRemoved:
      e.mutable_removed();
      break;
    case Kind::kParamsChanged:
      if (r.params) *e.mutable_params_changed()->mutable_params() = *r.params;
      break;
    case Kind::kControlApplied:
      if (r.request) *e.mutable_control_applied()->mutable_request() = *r.request;
      break;
  }
  return e;
}

std::string OutcomeReason(const RequestOutcome& o, const std::string& server_id) {
  using Why = RequestOutcome::Why;
  const std::string vehicle = "vehicle " + std::to_string(o.request ? o.request->vehicle_id() : 0);
  switch (o.why) {
    case Why::kNone:
      return {};
    case Why::kText:
      return o.text;
    case Why::kExists:
      return vehicle + " exists already";
    case Why::kFull:
      return "this server runs its maximum of " + std::to_string(o.max_vehicles) + " vehicles";
    case Why::kStepBehind:
      return "restore: " + vehicle + " is at step " + std::to_string(o.vehicle_step) +
             " and a vehicle's steps only go forward; restore step " +
             std::to_string(o.restore_step) + " into a fresh server or another vehicle id";
    case Why::kChanged:
      return vehicle + " on server '" + server_id +
             "' changed while this request waited (a request before it came first); send it "
             "again";
    case Why::kCancelledByPause:
      return "cancelled by a pause request before its steps were done";
    case Why::kCancelledByResume:
      return "cancelled by a resume request before its steps were done";
    case Why::kClientGone:
      return "its client went away before its steps were done";
    case Why::kStopped:
      return "the server stopped before its steps were done";
  }
  return {};
}

std::string ContainedWhy(StepStatus status) {
  if (status == StepStatus::kOk) return {};
  return std::string(StepStatusText(status)) +
         (status == StepStatus::kUnderGround
              ? ": put back on its wheels where it was"
              : status == StepStatus::kRunaway
                    ? ": put back at rest where it was (a parameter changed past what the model "
                      "resolves?)"
                    : ": put back at rest where it was (its parameters or input drive it past "
                      "what the step resolves?)");
}

void RequestOutcome::AddDiscarded(std::uint32_t vehicle_id, std::int64_t step, StepStatus status) {
  for (std::size_t i = 0; i < n_discarded; ++i) {
    if (discarded[i].vehicle_id == vehicle_id) {
      ++discarded[i].count;
      return;
    }
  }
  if (n_discarded == kDiscardedListed) {
    ++discarded_not_listed;  // a vehicle counted once per discarded step beyond the list
    return;
  }
  discarded[n_discarded++] = {vehicle_id, 1, step, status};
}

pb::ControlReply ToReply(const RequestOutcome& o, const std::string& server_id) {
  pb::ControlReply reply = messages::ReplyTo(o.request.get(), server_id);
  if (!o.accepted) messages::Refuse(reply, OutcomeReason(o, server_id));
  if (o.applied_step >= 0) reply.set_applied_step(static_cast<std::uint64_t>(o.applied_step));
  reply.set_sim_time_ns(o.sim_time_ns);
  for (std::size_t i = 0; i < o.n_discarded; ++i) {
    const RequestOutcome::Discarded& d = o.discarded[i];
    pb::DiscardedSteps* m = reply.add_discarded();
    m->set_vehicle_id(d.vehicle_id);
    m->set_count(d.count);
    m->set_first_step(static_cast<std::uint64_t>(d.first_step));
    m->set_reason(ContainedWhy(d.first_status));
  }
  reply.set_discarded_not_listed(o.discarded_not_listed);
  reply.set_steps_without_state(o.steps_without_state);
  return reply;
}

SessionVehicle NewVehicle(std::uint32_t id, std::shared_ptr<const World> world,
                          const SessionConfig& config,
                          std::shared_ptr<const pb::VehicleParams> params, const ValidParams& valid,
                          const State* exact, const Pose2& pose, double speed) {
  SimConfig sc;
  sc.step_ns = config.step_ns;
  SessionVehicle v;
  v.id = id;
  v.sim = std::make_unique<Simulator>(world, valid, sc, exact != nullptr ? *exact : State{});
  if (exact == nullptr) v.sim->Spawn(pose, speed);  // throws WorldError when it cannot start
  v.params = std::move(params);
  v.spawn_pose = pose;
  v.spawn_speed = speed;
  // Grown once here: the stepping thread copies ids into these and fills the state message.
  v.live_input.mutable_source_id()->reserve(limits::kMaxIdBytes);
  v.applied_msg.mutable_source_id()->reserve(limits::kMaxIdBytes);
  FillVehicleState(id, config.server_id, config.step_ns, 0, v.sim->last_step(), v.applied_msg, true,
                   0.0, v.state_msg);
  v.state_msg.set_incarnation(config.incarnation);  // FillVehicleState leaves it as set here
  v.state_msg.mutable_input()->mutable_source_id()->reserve(limits::kMaxIdBytes);
  return v;
}

Session::Session(std::shared_ptr<const World> world, SessionConfig config, EventSink on_event)
    : world_(std::move(world)),
      config_(std::move(config)),
      on_event_(std::move(on_event)),
      terrain_hash_(TerrainHash(world_->terrain)),
      pool_(config_.step_threads) {
  const auto issues = ValidateVehicleParams(config_.default_params);
  if (!issues.empty()) {
    throw std::invalid_argument("default vehicle parameters: " + FormatIssues(issues));
  }
  batch_steps_ = std::clamp<std::int64_t>(config_.input_batch_ns / config_.step_ns, 1,
                                          SessionEventRecord::kMaxBatchSamples);
  order_.reserve(std::max<std::size_t>(config_.max_vehicles, 1));
}

SessionEventRecord& Session::Begin(SessionEventRecord::Kind kind, std::uint32_t vehicle_id,
                                   std::int64_t step) {
  // Input changes gathered so far come first: the events of one vehicle stay in step order.
  if (const auto it = vehicles_.find(vehicle_id); it != vehicles_.end()) FlushInputs(it->second);
  SessionEventRecord& r = scratch_;
  r.kind = kind;
  r.vehicle_id = vehicle_id;
  r.step = step;
  r.sequence = event_sequence_++;
  r.params.reset();
  r.request.reset();
  r.world_name = nullptr;
  return r;
}

void Session::Emit() {
  if (on_event_) on_event_(std::move(scratch_));
  scratch_.params.reset();
  scratch_.request.reset();
}

void Session::FlushInputs(Vehicle& v) {
  if (v.n_pending == 0) return;
  SessionEventRecord& r = scratch_;
  r.kind = SessionEventRecord::Kind::kInputBatch;
  r.vehicle_id = v.id;
  r.step = v.pending[0].step;
  r.sequence = event_sequence_++;
  r.n_changes = v.n_pending;
  for (int i = 0; i < v.n_pending; ++i) r.changes[i] = v.pending[i];
  v.n_pending = 0;
  if (on_event_) on_event_(std::move(r));
}

void Session::SetStateForTesting(std::uint32_t id, const State& s) {
  Vehicle& v = vehicles_.at(id);
  v.sim->SetState(s);
  EmitSpawned(v);
}

void Session::FlushEvents() {
  for (auto& [id, v] : vehicles_) FlushInputs(v);
}

void Session::EmitSpawned(Vehicle& v, std::shared_ptr<const pb::ControlRequest> from) {
  SessionEventRecord& r = Begin(SessionEventRecord::Kind::kSpawned, v.id, v.sim->state().step);
  r.state = v.sim->state();
  r.params = v.params;
  r.world_name = &world_->name;
  r.request = std::move(from);
  Emit();
  v.applied_valid = false;  // the next latched input is announced again
}

void Session::Spawn(std::uint32_t vehicle_id, const Pose2& pose, double speed,
                    const pb::VehicleParams& params_update) {
  if (std::string bad = limits::Check(limits::kVehicleId, vehicle_id); !bad.empty()) {
    throw std::invalid_argument(bad);
  }
  if (vehicles_.count(vehicle_id) != 0) {
    throw std::invalid_argument("vehicle " + std::to_string(vehicle_id) + " exists already");
  }
  auto params = std::make_shared<const pb::VehicleParams>(
      MergeVehicleParams(config_.default_params, params_update));
  const auto issues = ValidateVehicleParams(*params);
  if (!issues.empty()) throw std::invalid_argument(FormatIssues(issues));
  if (vehicles_.size() >= config_.max_vehicles) {
    throw std::invalid_argument("this server runs its maximum of " +
                                std::to_string(config_.max_vehicles) + " vehicles");
  }
  Vehicle v = NewVehicle(vehicle_id, world_, config_, params, ParamsFromProto(*params), nullptr,
                         pose, speed);
  // A vehicle id used before in this session goes on counting where its last life ended, so
  // (vehicle, step) names one moment of the session.
  if (const auto r = retired_steps_.find(vehicle_id); r != retired_steps_.end()) {
    State s = v.sim->state();
    s.step = r->second;
    v.sim->SetState(s);
  }
  auto [it, inserted] = vehicles_.emplace(vehicle_id, std::move(v));
  order_stale_ = true;
  EmitSpawned(it->second);
}

RequestOutcome Session::Accept(const std::shared_ptr<const pb::ControlRequest>& r) {
  RequestOutcome o;
  o.request = r;
  o.accepted = true;
  o.sim_time_ns = steps_ * config_.step_ns;
  if (const auto it = vehicles_.find(r->vehicle_id()); it != vehicles_.end()) {
    o.applied_step = it->second.sim->state().step;
    SessionEventRecord& e =
        Begin(SessionEventRecord::Kind::kControlApplied, r->vehicle_id(), o.applied_step);
    e.request = r;
    Emit();
  }
  return o;
}

RequestOutcome Session::Refuse(const std::shared_ptr<const pb::ControlRequest>& r,
                               RequestOutcome::Why why) {
  RequestOutcome o;
  o.request = r;
  o.why = why;
  o.sim_time_ns = steps_ * config_.step_ns;
  if (const auto it = vehicles_.find(r->vehicle_id()); it != vehicles_.end()) {
    o.applied_step = it->second.sim->state().step;
  }
  return o;
}

RequestOutcome Session::Commit(PreparedRequest& p) {
  RequestOutcome o = CommitOperation(p);
  p.applied = o.accepted;
  return o;
}

bool Session::AsPlanned(const PreparedRequest& p, SessionVehicles::iterator it) const {
  using Op = PreparedRequest::Op;
  const bool about_vehicle =
      p.op == Op::kMove || p.op == Op::kRemove || p.op == Op::kSetParams || p.op == Op::kRestore;
  if (!about_vehicle) return true;
  const bool exists = it != vehicles_.end();
  return exists == (p.expected != nullptr) && (!exists || it->second.params == p.expected);
}

RequestOutcome Session::CommitOperation(PreparedRequest& p) {
  using Op = PreparedRequest::Op;
  const auto it = vehicles_.find(p.vehicle_id);
  // The vehicle is what the plan assumed (else a request planned before this one changed it).
  if (!AsPlanned(p, it)) return Refuse(p.request, RequestOutcome::Why::kChanged);
  switch (p.op) {
    case Op::kPause:
    case Op::kResume:
    case Op::kStep:
      return CommitPacing(p);
    case Op::kMove:
      return CommitMove(p, it->second);
    case Op::kSpawn:
      return CommitSpawn(p, it != vehicles_.end());
    case Op::kRemove:
      return CommitRemove(p, it);
    case Op::kSetParams:
      return CommitSetParams(p, it->second);
    case Op::kRestore:
      return CommitRestore(p, it);
  }
  return Refuse(p.request, RequestOutcome::Why::kChanged);
}

RequestOutcome Session::CommitPacing(const PreparedRequest& p) {
  switch (p.op) {
    case PreparedRequest::Op::kPause:
      paused_ = true;
      pending_steps_ = 0;
      break;
    case PreparedRequest::Op::kResume:
      paused_ = false;
      pending_steps_ = 0;
      break;
    default:  // kStep
      paused_ = true;
      pending_steps_ += p.steps;
      break;
  }
  return Accept(p.request);
}

RequestOutcome Session::CommitMove(const PreparedRequest& p, Vehicle& v) {
  State s = p.state;
  s.step = v.sim->state().step;  // the vehicle's step count goes on
  v.sim->SetState(s);
  RequestOutcome o = Accept(p.request);
  EmitSpawned(v);
  return o;
}

RequestOutcome Session::CommitSpawn(PreparedRequest& p, bool exists) {
  if (exists) return Refuse(p.request, RequestOutcome::Why::kExists);
  if (vehicles_.size() >= config_.max_vehicles) {
    RequestOutcome o = Refuse(p.request, RequestOutcome::Why::kFull);
    o.max_vehicles = static_cast<std::int64_t>(config_.max_vehicles);
    return o;
  }
  // A vehicle id used before in this session goes on counting where its last life ended.
  if (const auto ret = retired_steps_.find(p.vehicle_id); ret != retired_steps_.end()) {
    Simulator& sim = *p.vehicle.mapped().sim;
    State s = sim.state();
    s.step = ret->second;
    sim.SetState(s);
  }
  const auto ins = vehicles_.insert(std::move(p.vehicle));
  order_stale_ = true;
  EmitSpawned(ins.position->second);
  return Accept(p.request);
}

RequestOutcome Session::CommitRemove(PreparedRequest& p, SessionVehicles::iterator it) {
  RequestOutcome o = Accept(p.request);
  const std::int64_t step = it->second.sim->state().step;
  Begin(SessionEventRecord::Kind::kRemoved, p.vehicle_id, step);
  Emit();
  if (const auto ret = retired_steps_.find(p.vehicle_id); ret != retired_steps_.end()) {
    ret->second = step;
  } else {
    p.retired.key() = p.vehicle_id;
    p.retired.mapped() = step;
    retired_steps_.insert(std::move(p.retired));
  }
  p.replaced_vehicle = vehicles_.extract(it);
  order_stale_ = true;
  return o;
}

RequestOutcome Session::CommitSetParams(PreparedRequest& p, Vehicle& v) {
  v.sim->SetParams(*p.valid);  // checked against this step when planned
  p.replaced_params = std::exchange(v.params, std::move(p.params));
  RequestOutcome o = Accept(p.request);
  SessionEventRecord& e =
      Begin(SessionEventRecord::Kind::kParamsChanged, p.vehicle_id, v.sim->state().step);
  e.params = v.params;
  Emit();
  return o;
}

RequestOutcome Session::CommitRestore(PreparedRequest& p, SessionVehicles::iterator it) {
  const bool exists = it != vehicles_.end();
  // (vehicle, step) names one moment of a session: a vehicle's steps never go back.
  const std::int64_t step = p.vehicle.mapped().sim->state().step;
  std::int64_t floor = exists ? it->second.sim->state().step : 0;
  if (const auto ret = retired_steps_.find(p.vehicle_id); ret != retired_steps_.end()) {
    floor = std::max(floor, ret->second);
  }
  if (step < floor) {
    RequestOutcome o = Refuse(p.request, RequestOutcome::Why::kStepBehind);
    o.vehicle_step = floor;
    o.restore_step = step;
    return o;
  }
  if (!exists && vehicles_.size() >= config_.max_vehicles) {
    RequestOutcome o = Refuse(p.request, RequestOutcome::Why::kFull);
    o.max_vehicles = static_cast<std::int64_t>(config_.max_vehicles);
    return o;
  }
  if (exists) {
    // The old life ends here; the restored one starts at its own step (a re-simulation starts
    // afresh from the Spawned event).
    Begin(SessionEventRecord::Kind::kRemoved, p.vehicle_id, it->second.sim->state().step);
    Emit();
    p.replaced_vehicle = vehicles_.extract(it);
  }
  const auto ins = vehicles_.insert(std::move(p.vehicle));
  order_stale_ = true;
  EmitSpawned(ins.position->second, p.request);
  return Accept(p.request);
}

pb::ControlReply Session::Reject(const pb::ControlRequest& request, const std::string& reason) {
  RequestOutcome o;
  o.request = std::make_shared<const pb::ControlRequest>(request);
  o.why = RequestOutcome::Why::kText;
  o.text = reason;
  o.sim_time_ns = steps_ * config_.step_ns;
  if (const auto it = vehicles_.find(request.vehicle_id()); it != vehicles_.end()) {
    o.applied_step = it->second.sim->state().step;
  }
  return ToReply(o, config_.server_id);
}

pb::ControlReply Session::Apply(const pb::ControlRequest& request) {
  RequestPlanner planner(world_, config_);
  planner.Sync(*this);
  RequestPlanner::Plan plan = planner.Prepare(std::make_shared<const pb::ControlRequest>(request));
  if (plan.hello) {  // as the server answers it: accepted, nothing applied
    RequestOutcome o;
    o.request = std::make_shared<const pb::ControlRequest>(request);
    o.accepted = true;
    o.sim_time_ns = steps_ * config_.step_ns;
    return ToReply(o, config_.server_id);
  }
  if (!plan.prepared) return Reject(request, plan.refusal);
  const RequestOutcome o = Commit(*plan.prepared);
  planner.Settle(std::move(plan.prepared));
  return ToReply(o, config_.server_id);
}

bool Session::OfferInput(const pb::DriverInput& input, std::string* reason) {
  const auto it = vehicles_.find(input.vehicle_id());
  if (it == vehicles_.end()) {
    if (reason != nullptr) *reason = "no vehicle " + std::to_string(input.vehicle_id());
    return false;
  }
  const std::string bad = CheckInputRanges(input);
  if (!bad.empty()) {
    if (reason != nullptr) *reason = bad;
    return false;
  }
  Vehicle& v = it->second;
  v.live_input = input;
  v.input_restored = false;
  v.live_input_step = v.sim->state().step;
  return true;
}

double Session::input_age_s(std::uint32_t id) const {
  const Vehicle& v = vehicles_.at(id);
  if (v.live_input_step < 0) return std::numeric_limits<double>::infinity();
  return static_cast<double>(v.sim->state().step - v.live_input_step) * v.sim->h();
}

std::vector<std::uint32_t> Session::vehicle_ids() const {
  std::vector<std::uint32_t> ids;
  for (const auto& [id, v] : vehicles_) ids.push_back(id);
  return ids;
}

void Session::LatchInput(Vehicle& v) {
  // Watchdog: without live input for longer than watchdog_s the vehicle brakes, steering held.
  // Compared in whole steps: an input is live for watchdog_s after the boundary it arrived at.
  // The safe state keeps the last steering (angle and mode: a rig's hand-wheel angle stays a
  // hand-wheel angle, hands off stay off) and the last gear asked for (no surprise shift), drops
  // the throttle, clutch and handbrake, and brakes at safe_brake.
  const auto limit = static_cast<std::int64_t>(
      std::llround(config_.watchdog_s * 1e9 / static_cast<double>(config_.step_ns)));
  v.safe_state = v.live_input_step < 0 || v.sim->state().step - v.live_input_step > limit;
  DriverInput in;
  if (v.safe_state) {
    if (v.applied_valid) {
      in.steer = v.applied.steer;
      in.steer_mode = v.applied.steer_mode;
      in.gear = v.applied.gear;
    }
    in.brake = config_.safe_brake;
    v.applied_msg.Clear();
    v.applied_msg.set_vehicle_id(v.id);
    v.applied_msg.set_source_id("watchdog");
  } else {
    in = v.input_restored ? v.restored_input : FromProto(v.live_input);
    v.applied_msg = v.live_input;
  }
  v.sim->SetInput(in);
  const DriverInput& latched = v.sim->input();  // as the simulator sanitised it
  ToProto(latched, v.applied_msg);
  if (!v.applied_valid || !SamePhysics(latched, v.applied)) {
    if (v.n_pending == SessionEventRecord::kMaxBatchSamples) FlushInputs(v);
    v.pending[v.n_pending++] = {v.sim->state().step, latched};
    v.applied = latched;
    v.applied_valid = true;
  }
}

void Session::ContainNonFinite(Vehicle& v) {
  // Contained by the simulator (state kept at x_n, its last finite state); put the vehicle back
  // at rest where it is so the session goes on, and say so in the event stream. Where it cannot
  // rest (no ground below, inside a wall), it is stopped where it was: x_n at rest.
  const Eigen::Vector3d p = Position(v.sim->state().x);
  const double yaw = RollPitchYaw(Orientation(v.sim->state().x)).z();
  const std::int64_t step = v.sim->state().step;
  State last = v.sim->state();
  try {
    v.sim->Spawn({p.x(), p.y(), yaw}, 0.0);
  } catch (const std::exception&) {
    SetVelocity(last.x, Eigen::Vector3d::Zero());
    SetAngularVelocityB(last.x, Eigen::Vector3d::Zero());
    last.cruise_integral = 0.0;
    v.sim->SetState(last);
  }
  State s = v.sim->state();
  s.step = step + 1;
  v.sim->SetState(s);
  EmitSpawned(v);
}

void Session::StepPart(std::size_t begin, std::size_t end, Fill fill) {
  // Only the vehicle's own simulator and messages are written, and the world is only read: a
  // vehicle's result does not depend on the thread that steps it.
  const std::int64_t time_ns = steps_ * config_.step_ns;
  for (std::size_t i = begin; i < end; ++i) {
    Vehicle& v = *order_[i];
    v.step_status = v.sim->Step();
    const bool frame = fill == Fill::kEncoded && i < frames_open_;
    if (fill == Fill::kNone || v.step_status != StepStatus::kOk) {
      if (frame) frames_->Fill(i, v.id, 0, false);
      continue;
    }
    const StepRecord& r = v.sim->last_step();
    FillVehicleState(v.id, config_.server_id, config_.step_ns, time_ns, r, v.applied_msg,
                     v.safe_state, r.derived.steering_torque, v.state_msg);
    if (!frame) continue;
    const std::span<std::uint8_t> buffer = frames_->Buffer(i);
    const std::size_t size = v.state_msg.ByteSizeLong();
    const bool fits = size <= buffer.size();
    if (fits) v.state_msg.SerializeWithCachedSizesToArray(buffer.data());
    frames_->Fill(i, v.id, fits ? size : 0, !fits);
  }
}

void Session::Step(const StateSink& on_state) {
  StepPhases(on_state ? &on_state : nullptr, nullptr);
}

void Session::StepInto(StateFrames& frames) {
  StepPhases(nullptr, &frames);
}

void Session::StepPhases(const StateSink* on_state, StateFrames* frames) {
  if (order_stale_) {
    order_.clear();  // within its reserve: the vehicles are at most max_vehicles
    for (auto& [id, v] : vehicles_) order_.push_back(&v);
    order_stale_ = false;
  }
  // 1. Serial, in id order: inputs latched (a full batch of input changes goes out as an event).
  for (Vehicle* v : order_) LatchInput(*v);
  // 2. The pool: each vehicle's step and its own state message (encoded into its frame).
  const Fill fill = frames != nullptr     ? Fill::kEncoded
                    : on_state != nullptr ? Fill::kMessage
                                          : Fill::kNone;
  frames_ = frames;
  frames_open_ = frames != nullptr ? frames->Open(order_.size()) : 0;
  auto part = [this, fill](std::size_t begin, std::size_t end) { StepPart(begin, end, fill); };
  pool_.Run(order_.size(), part);
  // 3. Serial, in id order: what goes out (events, states), as if one thread had done it all.
  for (Vehicle* vp : order_) {
    Vehicle& v = *vp;
    const std::uint32_t id = v.id;
    if (v.step_status != StepStatus::kOk) {
      ContainNonFinite(v);
      continue;
    }
    if (on_state != nullptr) (*on_state)(id, v.state_msg);
    const std::int64_t step = v.sim->state().step;
    if (v.n_pending > 0 && step - v.pending[0].step >= batch_steps_) FlushInputs(v);
    if (config_.checkpoint_every_steps > 0 && step % config_.checkpoint_every_steps == 0) {
      FlushInputs(v);
      SessionEventRecord& c = scratch_;
      c.kind = SessionEventRecord::Kind::kCheckpoint;
      c.vehicle_id = id;
      c.step = step;
      c.sequence = event_sequence_++;
      c.state = v.sim->state();
      c.input = v.sim->input();
      c.params = v.params;
      if (on_event_) on_event_(std::move(c));
      c.params.reset();
    }
  }
  // The frames go out after the events of the step (as the states did before them).
  if (frames != nullptr) frames->Close(order_.size());
  frames_ = nullptr;
  ++steps_;
}

}  // namespace vdyn
