#include "vdyn/runtime/session.h"

#include <cmath>
#include <limits>
#include <stdexcept>

#include "vdyn/base/limits.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/bridge/params.h"

namespace vdyn {
namespace {

Pose2 FromProto(const pb::Pose2& p) { return {p.x(), p.y(), p.yaw()}; }

bool SamePhysics(const DriverInput& a, const DriverInput& b) {
  return a.steer == b.steer && a.throttle == b.throttle && a.brake == b.brake &&
         a.cruise_on == b.cruise_on && a.cruise_speed == b.cruise_speed &&
         a.steer_mode == b.steer_mode && a.clutch == b.clutch && a.handbrake == b.handbrake &&
         a.gear == b.gear;
}

std::string CheckPose(const pb::Pose2& p, double speed) {
  for (const std::string& why : {limits::Check(limits::kPoseXY, p.x()),
                                 limits::Check(limits::kPoseXY, p.y()),
                                 limits::Check(limits::kPoseYaw, p.yaw()),
                                 limits::Check(limits::kSpawnSpeed, speed)}) {
    if (!why.empty()) return why;
  }
  return {};
}

}  // namespace

std::string CheckInputRanges(const pb::DriverInput& in) {
  if (!pb::SteerMode_IsValid(in.steer_mode())) {
    return "steer_mode " + std::to_string(in.steer_mode()) + " is not a steer mode";
  }
  const limits::Range& steer =
      in.steer_mode() == pb::STEER_HAND_WHEEL ? limits::kHandWheel : limits::kSteer;
  for (const std::string& why : {limits::Check(steer, in.steer()),
                                 limits::Check(limits::kThrottle, in.throttle()),
                                 limits::Check(limits::kBrake, in.brake()),
                                 limits::Check(limits::kCruiseSetKmh, in.cruise_set_kmh()),
                                 limits::Check(limits::kClutch, in.clutch()),
                                 limits::Check(limits::kHandbrake, in.handbrake()),
                                 limits::Check(limits::kGear, in.gear())}) {
    if (!why.empty()) return why;
  }
  return {};
}

pb::SessionEvent ToMessage(const SessionEventRecord& r, const std::string& server_id,
                           std::uint64_t terrain_hash, std::int64_t step_ns) {
  pb::SessionEvent e;
  if (r.kind == SessionEventRecord::Kind::kMessage && r.message) e = *r.message;
  e.set_vehicle_id(r.vehicle_id);
  e.set_server_id(server_id);
  e.set_step(static_cast<std::uint64_t>(r.step));
  e.set_sequence(r.sequence);
  if (r.kind == SessionEventRecord::Kind::kInputBatch) {
    auto* batch = e.mutable_input_batch();
    for (int i = 0; i < r.n_changes; ++i) {
      ToInputSample(r.changes[i].input, r.changes[i].step, *batch->add_samples());
    }
  } else if (r.kind == SessionEventRecord::Kind::kCheckpoint) {
    auto* c = e.mutable_checkpoint();
    *c->mutable_state() = ToExactState(r.state);
    if (r.params) *c->mutable_params() = *r.params;
    ToInputSample(r.input, r.step, *c->mutable_input());
    c->set_terrain_hash(terrain_hash);
    c->set_step_ns(step_ns);
  }
  return e;
}

Session::Session(std::shared_ptr<const World> world, SessionConfig config, EventSink on_event)
    : world_(std::move(world)),
      config_(std::move(config)),
      on_event_(std::move(on_event)),
      terrain_hash_(TerrainHash(world_->terrain)) {
  const auto issues = ValidateVehicleParams(config_.default_params);
  if (!issues.empty()) {
    throw std::invalid_argument("default vehicle parameters: " + FormatIssues(issues));
  }
  batch_steps_ = std::clamp<std::int64_t>(config_.input_batch_ns / config_.step_ns, 1,
                                          SessionEventRecord::kMaxBatchSamples);
}

void Session::EmitMessage(std::uint32_t vehicle_id, std::int64_t step,
                          std::unique_ptr<pb::SessionEvent> e) {
  // Input changes gathered so far come first: the events of one vehicle stay in step order.
  if (const auto it = vehicles_.find(vehicle_id); it != vehicles_.end()) FlushInputs(it->second);
  SessionEventRecord& r = scratch_;
  r.kind = SessionEventRecord::Kind::kMessage;
  r.vehicle_id = vehicle_id;
  r.step = step;
  r.sequence = event_sequence_++;
  r.message = std::move(e);
  if (on_event_) on_event_(std::move(r));
  r.message.reset();
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

void Session::EmitSpawned(Vehicle& v, const std::string& branched_from) {
  auto e = std::make_unique<pb::SessionEvent>();
  auto* s = e->mutable_spawned();
  s->set_branched_from(branched_from);
  *s->mutable_state() = ToExactState(v.sim->state());
  *s->mutable_params() = *v.params;
  s->set_world_name(world_->name);
  s->set_terrain_hash(terrain_hash_);
  s->set_step_ns(config_.step_ns);
  EmitMessage(v.id, v.sim->state().step, std::move(e));
  v.applied_valid = false;  // the next latched input is announced again
}

void Session::Spawn(std::uint32_t vehicle_id, const Pose2& pose, double speed,
                    const pb::VehicleParams& params_update) {
  if (vehicles_.count(vehicle_id) != 0) {
    throw std::invalid_argument("vehicle " + std::to_string(vehicle_id) + " exists already");
  }
  const pb::VehicleParams params = MergeVehicleParams(config_.default_params, params_update);
  const auto issues = ValidateVehicleParams(params);
  if (!issues.empty()) throw std::invalid_argument(FormatIssues(issues));
  if (vehicles_.size() >= config_.max_vehicles) {
    throw std::invalid_argument("this server runs its maximum of " +
                                std::to_string(config_.max_vehicles) + " vehicles");
  }
  SimConfig sc;
  sc.step_ns = config_.step_ns;
  Vehicle v;
  v.id = vehicle_id;
  v.sim = std::make_unique<Simulator>(world_, ParamsFromProto(params), sc, State{});
  v.sim->Spawn(pose, speed);  // throws WorldError when no terrain is below
  // A vehicle id used before in this session goes on counting where its last life ended, so
  // (vehicle, step) names one moment of the session.
  if (const auto r = retired_steps_.find(vehicle_id); r != retired_steps_.end()) {
    State s = v.sim->state();
    s.step = r->second;
    v.sim->SetState(s);
  }
  v.params = std::make_shared<const pb::VehicleParams>(params);
  v.spawn_pose = pose;
  v.spawn_speed = speed;
  auto [it, inserted] = vehicles_.emplace(vehicle_id, std::move(v));
  EmitSpawned(it->second);
}

pb::ControlReply Session::Reply(const pb::ControlRequest& r, bool accepted,
                                const std::string& reason) {
  pb::ControlReply reply;
  reply.set_request_id(r.request_id());
  reply.set_client_id(r.client_id());
  reply.set_vehicle_id(r.vehicle_id());
  reply.set_server_id(config_.server_id);
  reply.set_accepted(accepted);
  reply.set_reason(reason);
  const auto it = vehicles_.find(r.vehicle_id());
  if (it != vehicles_.end()) {
    reply.set_applied_step(static_cast<std::uint64_t>(it->second.sim->state().step));
  }
  reply.set_sim_time_ns(steps_ * config_.step_ns);
  if (accepted && it != vehicles_.end()) {
    auto e = std::make_unique<pb::SessionEvent>();
    *e->mutable_control_applied()->mutable_request() = r;
    EmitMessage(r.vehicle_id(), it->second.sim->state().step, std::move(e));
  }
  return reply;
}

pb::ControlReply Session::Apply(const pb::ControlRequest& r) {
  const auto it = vehicles_.find(r.vehicle_id());
  const bool exists = it != vehicles_.end();
  const std::string no_vehicle = "no vehicle " + std::to_string(r.vehicle_id()) + " on server '" +
                                 config_.server_id + "'";
  switch (r.command_case()) {
    case pb::ControlRequest::kPause:
      paused_ = true;
      pending_steps_ = 0;
      return Reply(r, true, {});
    case pb::ControlRequest::kResume:
      paused_ = false;
      pending_steps_ = 0;
      return Reply(r, true, {});
    case pb::ControlRequest::kStep:
      if (r.step().steps() == 0) return Reply(r, false, "step needs steps >= 1");
      if (r.step().steps() > limits::kMaxStepsPerRequest) {
        return Reply(r, false, "step asks for more than " +
                                   std::to_string(limits::kMaxStepsPerRequest) +
                                   " steps; ask in several requests");
      }
      paused_ = true;
      pending_steps_ += r.step().steps();
      return Reply(r, true, {});
    case pb::ControlRequest::kReset:
    case pb::ControlRequest::kTeleport: {
      if (!exists) return Reply(r, false, no_vehicle);
      Vehicle& v = it->second;
      Pose2 pose = v.spawn_pose;
      double speed = 0.0;
      if (r.has_teleport()) {
        const std::string bad = CheckPose(r.teleport().pose(), r.teleport().speed());
        if (!bad.empty()) return Reply(r, false, bad);
        pose = FromProto(r.teleport().pose());
        speed = r.teleport().speed();
      }
      try {
        const std::int64_t step = v.sim->state().step;
        v.sim->Spawn(pose, speed);
        State s = v.sim->state();
        s.step = step;  // the vehicle's step count goes on
        v.sim->SetState(s);
      } catch (const std::exception& e) {
        return Reply(r, false, e.what());
      }
      pb::ControlReply reply = Reply(r, true, {});
      EmitSpawned(v);
      return reply;
    }
    case pb::ControlRequest::kSpawn: {
      if (exists) {
        return Reply(r, false, "vehicle " + std::to_string(r.vehicle_id()) + " exists already");
      }
      if (r.server_id().empty()) {
        // Every server in the domain would take it and two vehicles would share one key.
        return Reply(r, false, "spawn needs server_id: several servers may share the domain");
      }
      const std::string bad = CheckPose(r.spawn().pose(), r.spawn().speed());
      if (!bad.empty()) return Reply(r, false, bad);
      try {
        Spawn(r.vehicle_id(), FromProto(r.spawn().pose()), r.spawn().speed(), r.spawn().params());
      } catch (const std::exception& e) {
        return Reply(r, false, e.what());
      }
      return Reply(r, true, {});
    }
    case pb::ControlRequest::kRemove: {
      if (!exists) return Reply(r, false, no_vehicle);
      pb::ControlReply reply = Reply(r, true, {});
      auto e = std::make_unique<pb::SessionEvent>();
      e->mutable_removed();
      EmitMessage(r.vehicle_id(), it->second.sim->state().step, std::move(e));
      retired_steps_[r.vehicle_id()] = it->second.sim->state().step;
      vehicles_.erase(it);
      return reply;
    }
    case pb::ControlRequest::kSetParams: {
      if (!exists) return Reply(r, false, no_vehicle);
      Vehicle& v = it->second;
      const pb::VehicleParams merged = MergeVehicleParams(*v.params, r.set_params().params());
      const auto issues = ValidateVehicleParams(merged);
      if (!issues.empty()) return Reply(r, false, FormatIssues(issues));
      const ValidParams valid = ParamsFromProto(merged);
      if (const std::string why = CheckStep(valid, v.sim->h()); !why.empty()) {
        return Reply(r, false, why);
      }
      v.params = std::make_shared<const pb::VehicleParams>(merged);
      v.sim->SetParams(valid);
      pb::ControlReply reply = Reply(r, true, {});
      auto e = std::make_unique<pb::SessionEvent>();
      *e->mutable_params_changed()->mutable_params() = merged;
      EmitMessage(v.id, v.sim->state().step, std::move(e));
      return reply;
    }
    case pb::ControlRequest::kRestore:
      return Restore(r);
    case pb::ControlRequest::kPlayback:
      return Reply(r, false, "playback requests are for a player (vdyn-recorder play), not a server");
    case pb::ControlRequest::COMMAND_NOT_SET:
      break;
  }
  return Reply(r, false, "the request names no command");
}

pb::ControlReply Session::Restore(const pb::ControlRequest& r) {
  const pb::ControlRequest::Restore& rs = r.restore();
  const std::uint32_t id = r.vehicle_id();
  const auto it = vehicles_.find(id);
  State state;
  try {
    state = FromExactState(rs.state());
  } catch (const std::exception& e) {
    return Reply(r, false, std::string("restore: ") + e.what());
  }
  if (state.step < 0) return Reply(r, false, "restore: the state's step is beyond range");
  // (vehicle, step) names one moment of a session: a vehicle's steps never go back.
  std::int64_t floor = 0;
  if (it != vehicles_.end()) floor = it->second.sim->state().step;
  if (const auto ret = retired_steps_.find(id); ret != retired_steps_.end()) {
    floor = std::max(floor, ret->second);
  }
  if (state.step < floor) {
    return Reply(r, false, "restore: vehicle " + std::to_string(id) + " is at step " +
                               std::to_string(floor) + " and a vehicle's steps only go forward; " +
                               "restore step " + std::to_string(state.step) +
                               " into a fresh server or another vehicle id");
  }
  const pb::VehicleParams params = MergeVehicleParams(config_.default_params, rs.params());
  const auto issues = ValidateVehicleParams(params);
  if (!issues.empty()) return Reply(r, false, "restore: " + FormatIssues(issues));
  if (it == vehicles_.end()) {
    if (r.server_id().empty()) {
      return Reply(r, false, "restore of a new vehicle needs server_id, as spawn does");
    }
    if (vehicles_.size() >= config_.max_vehicles) {
      return Reply(r, false, "this server runs its maximum of " +
                                 std::to_string(config_.max_vehicles) + " vehicles");
    }
  }
  const ValidParams valid = ParamsFromProto(params);
  if (it != vehicles_.end()) {
    // The old life ends here; the restored one starts at its own step (a re-simulation starts
    // afresh from the Spawned event).
    auto removed = std::make_unique<pb::SessionEvent>();
    removed->mutable_removed();
    EmitMessage(id, it->second.sim->state().step, std::move(removed));
    vehicles_.erase(it);
  }
  SimConfig sc;
  sc.step_ns = config_.step_ns;
  Vehicle v;
  v.id = id;
  v.sim = std::make_unique<Simulator>(world_, valid, sc, state);
  v.params = std::make_shared<const pb::VehicleParams>(params);
  const Eigen::Vector3d p = Position(state.x);
  v.spawn_pose = {p.x(), p.y(), RollPitchYaw(Orientation(state.x)).z()};
  v.spawn_speed = 0.0;
  // The restored input drives until a live input arrives; the watchdog counts from here.
  v.restored_input = FromInputSample(rs.input());
  v.input_restored = true;
  v.live_input.set_vehicle_id(id);
  v.live_input.set_source_id("restore");
  v.live_input_step = state.step;
  auto [ins, inserted] = vehicles_.emplace(id, std::move(v));
  EmitSpawned(ins->second, rs.branched_from());
  return Reply(r, true, {});
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

void Session::Step(const StateSink& on_state) {
  for (auto& [id, v] : vehicles_) {
    LatchInput(v);
    if (v.sim->Step() != StepStatus::kOk) {
      // Contained by the simulator (state kept at x_n, its last finite state); put the vehicle
      // back at rest where it is so the session goes on, and say so in the event stream. Where it
      // cannot rest (no ground below, inside a wall), it is stopped where it was: x_n at rest.
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
      continue;
    }
    const StepRecord& r = v.sim->last_step();
    if (on_state) {
      FillVehicleState(id, config_.server_id, config_.step_ns, steps_ * config_.step_ns, r,
                       v.applied_msg, v.safe_state, r.derived.steering_torque, v.state_msg);
      on_state(id, v.state_msg);
    }
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
  ++steps_;
}

}  // namespace vdyn
