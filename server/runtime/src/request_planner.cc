#include "vdyn/base/text.h"
#include "vdyn/runtime/request_planner.h"

#include <stdexcept>

#include "vdyn/base/limits.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/bridge/params.h"

namespace vdyn {
namespace {

using Op = PreparedRequest::Op;
constexpr double kMaxRestoreHeightM = 100.0;

Pose2 FromProto(const pb::Pose2& p) {
  return {p.x(), p.y(), p.yaw()};
}

std::string CheckPose(const pb::Pose2& p, double speed) {
  for (const std::string& why :
       {limits::Check(limits::kPoseXY, p.x()), limits::Check(limits::kPoseXY, p.y()),
        limits::Check(limits::kPoseYaw, p.yaw()), limits::Check(limits::kSpawnSpeed, speed)}) {
    if (!why.empty()) return why;
  }
  return {};
}

// A restored state must be one a server could have saved: spawn and teleport check the pose,
// restore took any finite state (a car 1e9 m out with no terrain, falling for ever; one 1000 km
// up; a zero quaternion; a car at 1e5 m/s).
std::string CheckRestoredState(const State& s, const Terrain& terrain) {
  const Eigen::Vector3d p = Position(s.x);
  const double q = s.x.segment<4>(sx::kQ).norm();
  if (std::abs(q - 1.0) > 1e-6) {
    return "its orientation quaternion has norm " + base::FormatApprox(q) +
           ", not 1: not a state a server saved (checkpoints carry them exactly)";
  }
  for (const std::string& why :
       {limits::Check(limits::kPoseXY, p.x()), limits::Check(limits::kPoseXY, p.y())}) {
    if (!why.empty()) return why;
  }
  if (Velocity(s.x).norm() > kRunawaySpeedMps ||
      AngularVelocityB(s.x).norm() > kRunawayRateRadps) {
    return "it moves faster than 1000 m/s or spins faster than 1000 rad/s: no vehicle does";
  }
  const TraceHit ground = terrain.GroundBelow(p.x(), p.y());
  if (!ground.hit) {
    return "no terrain under its position (" + base::FormatApprox(p.x(), 6) + ", " +
           base::FormatApprox(p.y(), 6) + ") m: it would fall for ever";
  }
  const double height = p.z() - (terrain.above_all_z() - ground.distance);
  if (height > kMaxRestoreHeightM || height < -kMaxRestoreHeightM) {
    return "it is " + base::FormatApprox(std::abs(height)) + " m " +
           (height > 0 ? "above" : "below") +
           " the ground under it (at most " + base::FormatNumber(kMaxRestoreHeightM) +
           " m either way: a car in a jump, not one dropped from the sky)";
  }
  return {};
}

SessionVehicles::node_type Node(SessionVehicle v) {
  SessionVehicles one;
  const std::uint32_t id = v.id;
  one.emplace(id, std::move(v));
  return one.extract(id);
}

}  // namespace

RequestPlanner::RequestPlanner(std::shared_ptr<const World> world, SessionConfig config)
    : world_(std::move(world)),
      config_(std::move(config)),
      h_(static_cast<double>(config_.step_ns) * 1e-9) {}

void RequestPlanner::Sync(const Session& session) {
  vehicles_.clear();
  for (const auto& [id, v] : session.vehicles()) {
    vehicles_[id] = {v.params, nullptr, v.spawn_pose};
  }
}

const ValidParams& RequestPlanner::Valid(Known& k) {
  if (!k.valid) k.valid = std::make_shared<const ValidParams>(ParamsFromProto(*k.params));
  return *k.valid;
}

RequestPlanner::Plan RequestPlanner::Prepare(std::shared_ptr<const pb::ControlRequest> request) {
  const pb::ControlRequest& r = *request;
  Plan plan;
  auto p = std::make_unique<PreparedRequest>();
  p->request = request;
  p->vehicle_id = r.vehicle_id();
  const auto known = vehicles_.find(r.vehicle_id());
  if (known != vehicles_.end()) p->expected = known->second.params;
  const std::string no_vehicle =
      "no vehicle " + std::to_string(r.vehicle_id()) + " on server '" + config_.server_id + "'";
  std::string& why = plan.refusal;
  switch (r.command_case()) {
    case pb::ControlRequest::kPause:
      p->op = Op::kPause;
      break;
    case pb::ControlRequest::kResume:
      p->op = Op::kResume;
      break;
    case pb::ControlRequest::kStep:
      p->op = Op::kStep;
      if (r.step().steps() == 0) {
        why = "step needs steps >= 1";
      } else if (r.step().steps() > limits::kMaxStepsPerRequest) {
        why = "step asks for more than " + std::to_string(limits::kMaxStepsPerRequest) +
              " steps; ask in several requests";
      }
      p->steps = r.step().steps();
      if (why.empty() && r.step().has_input() && r.step().input().vehicle_id() != 0) {
        const pb::DriverInput& in = r.step().input();
        if (!Knows(in.vehicle_id())) {
          plan.bad_step_input = "no vehicle " + std::to_string(in.vehicle_id());
        } else {
          plan.bad_step_input = CheckInputRanges(in);
        }
        p->step_input = plan.bad_step_input.empty();
      }
      break;
    case pb::ControlRequest::kReset:
    case pb::ControlRequest::kTeleport:
      p->op = Op::kMove;
      why = known == vehicles_.end() ? no_vehicle : PlanMove(r, known->second, *p);
      break;
    case pb::ControlRequest::kSpawn:
      p->op = Op::kSpawn;
      why = PlanSpawn(r, *p);
      break;
    case pb::ControlRequest::kRemove:
      p->op = Op::kRemove;
      if (known == vehicles_.end()) {
        why = no_vehicle;
      } else {
        // A node for the step it ends at (the session remembers it, allocating nothing).
        std::map<std::uint32_t, std::int64_t> one{{r.vehicle_id(), 0}};
        p->retired = one.extract(r.vehicle_id());
        vehicles_.erase(known);
      }
      break;
    case pb::ControlRequest::kSetParams:
      p->op = Op::kSetParams;
      why = known == vehicles_.end() ? no_vehicle : PlanSetParams(r, known->second, *p);
      break;
    case pb::ControlRequest::kRestore:
      p->op = Op::kRestore;
      why = PlanRestore(r, *p);
      break;
    case pb::ControlRequest::kPlayback:
      why = "playback requests are for a player (vdyn-recorder play), not a server";
      break;
    case pb::ControlRequest::kHello:
      plan.hello = true;
      return plan;
    case pb::ControlRequest::COMMAND_NOT_SET:
      why = "the request names no command";
      break;
  }
  if (why.empty()) plan.prepared = std::move(p);
  return plan;
}

std::string RequestPlanner::PlanMove(const pb::ControlRequest& r, Known& k, PreparedRequest& p) {
  Pose2 pose = k.spawn_pose;
  double speed = 0.0;
  if (r.has_teleport()) {
    if (std::string bad = CheckPose(r.teleport().pose(), r.teleport().speed()); !bad.empty()) {
      return bad;
    }
    pose = FromProto(r.teleport().pose());
    speed = r.teleport().speed();
  }
  // What Simulator::Spawn does, here: the resting state and whether the body fits there.
  try {
    const ValidParams& valid = Valid(k);
    double misfit = 0.0;
    p.state = RestingState(valid.get(), world_->terrain, pose, speed, &misfit);
    if (std::string obstruction = SpawnObstruction(valid.get(), world_->terrain, p.state, misfit);
        !obstruction.empty()) {
      return obstruction;
    }
  } catch (const std::exception& e) {
    return e.what();
  }
  return {};
}

std::string RequestPlanner::PlanSpawn(const pb::ControlRequest& r, PreparedRequest& p) {
  const std::uint32_t id = r.vehicle_id();
  if (std::string bad = limits::Check(limits::kVehicleId, id); !bad.empty()) return bad;
  if (Knows(id)) return "vehicle " + std::to_string(id) + " exists already";
  if (r.server_id().empty()) {
    // Every server in the domain would take it and two vehicles would share one key.
    return "spawn needs server_id: several servers may share the domain";
  }
  if (std::string bad = CheckPose(r.spawn().pose(), r.spawn().speed()); !bad.empty()) return bad;
  if (vehicles_.size() >= config_.max_vehicles) {
    return "this server runs its maximum of " + std::to_string(config_.max_vehicles) + " vehicles";
  }
  auto params = std::make_shared<const pb::VehicleParams>(
      MergeVehicleParams(config_.default_params, r.spawn().params()));
  if (const auto issues = ValidateVehicleParams(*params); !issues.empty()) {
    return FormatIssues(issues);
  }
  const Pose2 pose = FromProto(r.spawn().pose());
  try {
    auto valid = std::make_shared<const ValidParams>(ParamsFromProto(*params));
    p.vehicle =
        Node(NewVehicle(id, world_, config_, params, *valid, nullptr, pose, r.spawn().speed()));
    vehicles_[id] = {params, valid, pose};
  } catch (const std::exception& e) {
    return e.what();
  }
  return {};
}

std::string RequestPlanner::PlanSetParams(const pb::ControlRequest& r, Known& k,
                                          PreparedRequest& p) {
  auto merged = std::make_shared<const pb::VehicleParams>(
      MergeVehicleParams(*k.params, r.set_params().params()));
  if (const auto issues = ValidateVehicleParams(*merged); !issues.empty()) {
    return FormatIssues(issues);
  }
  // A wheel on a tyre file rolls on its UNLOADED_RADIUS: a radius asked for it would be shown
  // and never used (it was accepted so).
  const pb::VehicleParams& asked = r.set_params().params();
  const std::pair<const char*, const pb::WheelParams*> wheels[] = {
      {"lf", &asked.lf()}, {"rf", &asked.rf()}, {"lr", &asked.lr()}, {"rr", &asked.rr()}};
  const pb::WheelParams* after[] = {&merged->lf(), &merged->rf(), &merged->lr(), &merged->rr()};
  const pb::WheelParams* before[] = {&k.params->lf(), &k.params->rf(), &k.params->lr(),
                                     &k.params->rr()};
  for (int w = 0; w < 4; ++w) {
    if (wheels[w].second->has_radius() && after[w]->has_magic_formula() &&
        wheels[w].second->radius() != before[w]->radius()) {
      return std::string(wheels[w].first) + ".radius: this wheel's tyre file sets its radius (" +
             "UNLOADED_RADIUS " + base::FormatNumber(after[w]->magic_formula().unloaded_radius()) +
             " m): change the tyre's unloaded_radius, or remove the tyre";
    }
  }
  auto valid = std::make_shared<const ValidParams>(ParamsFromProto(*merged));
  if (std::string why = CheckStep(*valid, h_); !why.empty()) return why;
  p.params = merged;
  p.valid = *valid;
  k.params = std::move(merged);
  k.valid = std::move(valid);
  return {};
}

std::string RequestPlanner::PlanRestore(const pb::ControlRequest& r, PreparedRequest& p) {
  const pb::ControlRequest::Restore& rs = r.restore();
  const std::uint32_t id = r.vehicle_id();
  if (std::string bad = limits::Check(limits::kVehicleId, id); !bad.empty()) {
    return "restore: " + bad;
  }
  State state;
  try {
    state = FromExactState(rs.state());
  } catch (const std::exception& e) {
    return std::string("restore: ") + e.what();
  }
  if (state.step < 0) return "restore: the state's step is beyond range";
  if (std::string bad = CheckRestoredState(state, world_->terrain); !bad.empty()) {
    return "restore: " + bad;
  }
  auto params = std::make_shared<const pb::VehicleParams>(
      MergeVehicleParams(config_.default_params, rs.params()));
  if (const auto issues = ValidateVehicleParams(*params); !issues.empty()) {
    return "restore: " + FormatIssues(issues);
  }
  if (!Knows(id)) {
    if (r.server_id().empty()) return "restore of a new vehicle needs server_id, as spawn does";
    if (vehicles_.size() >= config_.max_vehicles) {
      return "this server runs its maximum of " + std::to_string(config_.max_vehicles) +
             " vehicles";
    }
  }
  try {
    auto valid = std::make_shared<const ValidParams>(ParamsFromProto(*params));
    SessionVehicle v = NewVehicle(id, world_, config_, params, *valid, &state, {}, 0.0);
    const Eigen::Vector3d pos = Position(v.sim->state().x);
    v.spawn_pose = {pos.x(), pos.y(), RollPitchYaw(Orientation(v.sim->state().x)).z()};
    v.spawn_speed = 0.0;
    // The restored input drives until a live input arrives; the watchdog counts from here.
    v.restored_input = FromInputSample(rs.input());
    v.input_restored = true;
    v.live_input.set_vehicle_id(id);
    v.live_input.set_source_id("restore");
    v.live_input_step = v.sim->state().step;
    waiting_known_ = {params, valid, v.spawn_pose};
    p.vehicle = Node(std::move(v));
  } catch (const std::exception& e) {
    return std::string("restore: ") + e.what();
  }
  waiting_ = &p;
  return {};
}

void RequestPlanner::Settle(std::unique_ptr<PreparedRequest> spent) {
  if (spent.get() == waiting_) {
    if (spent->applied) vehicles_[spent->vehicle_id] = std::move(waiting_known_);
    waiting_known_ = {};
    waiting_ = nullptr;
  }
  spent.reset();  // the replaced vehicle, parameters and nodes, and the request, freed here
}

}  // namespace vdyn
