#include "vdyn/replay/resim.h"

#include <algorithm>

#include "vdyn/bridge/convert.h"
#include "vdyn/bridge/params.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/physics/world.h"

namespace vdyn {

// The replay's own: its actions, where it stands, and the simulator (never handed out).
struct VehicleReplayer::Impl {
  struct Action {
    enum class Kind { kSpawned, kCheckpoint, kInput, kParams, kRemoved } kind;
    std::uint64_t step = 0;
    State state;
    DriverInput input;
    std::shared_ptr<const ValidParams> params;
    std::int64_t step_ns = 0;
  };
  bool Add(const pb::SessionEvent& e, std::string* error);
  bool Apply(const Action& a, std::string* error);
  bool Run(std::uint64_t end_step, const std::function<void(std::uint64_t, std::uint64_t)>& on_step,
           std::string* error);

  std::shared_ptr<const World> world_;
  std::uint64_t terrain_hash_ = 0;
  std::uint32_t vehicle_id_ = 0;
  std::vector<Action> actions_;
  std::size_t next_ = 0;  // the next action to apply
  bool started_ = false;
  std::unique_ptr<Simulator> sim_;
};

ReplayWorld ReplayWorldFrom(const pb::WorldDescription& description) {
  ReplayWorld w;
  w.world = WorldFromDescription(description);
  w.terrain_hash = TerrainHash(w.world->terrain);
  return w;
}

VehicleReplayer::VehicleReplayer(std::shared_ptr<const World> world, std::uint64_t terrain_hash,
                                 std::uint32_t vehicle_id)
    : impl_(std::make_unique<Impl>()) {
  impl_->world_ = std::move(world);
  impl_->terrain_hash_ = terrain_hash;
  impl_->vehicle_id_ = vehicle_id;
}

VehicleReplayer::~VehicleReplayer() = default;

bool VehicleReplayer::Add(const pb::SessionEvent& e, std::string* error) {
  return impl_->Add(e, error);
}

bool VehicleReplayer::Run(std::uint64_t end_step,
                          const std::function<void(std::uint64_t, std::uint64_t)>& on_step,
                          std::string* error) {
  return impl_->Run(end_step, on_step, error);
}

std::optional<std::uint64_t> VehicleReplayer::last_step() const {
  if (!impl_->sim_) return std::nullopt;
  return static_cast<std::uint64_t>(impl_->sim_->last_step().step);
}

std::optional<pb::VehicleState> VehicleReplayer::StateMessage(
    const pb::VehicleState& recorded) const {
  if (!impl_->sim_) return std::nullopt;
  const Simulator& sim = *impl_->sim_;
  const StepRecord& rec = sim.last_step();
  pb::DriverInput input = recorded.input();
  ToProto(rec.input, input);
  pb::VehicleState out;
  FillVehicleState(recorded.vehicle_id(), recorded.server_id(), sim.step_ns(),
                   recorded.sim_time_ns(), rec, input, recorded.control().watchdog_safe_state(),
                   rec.derived.steering_torque, out);
  out.set_incarnation(recorded.incarnation());
  return out;
}

std::optional<VehicleReplayer::Exact> VehicleReplayer::ExactAt(std::uint64_t step) const {
  const Simulator* sim = impl_->sim_.get();
  if (sim == nullptr || static_cast<std::uint64_t>(sim->state().step) != step) return std::nullopt;
  Exact e;
  e.state = ToExactState(sim->state());
  ToInputSample(sim->input(), static_cast<std::int64_t>(step), e.input);
  return e;
}

bool VehicleReplayer::Impl::Add(const pb::SessionEvent& e, std::string* error) {
  const std::string who = "vehicle " + std::to_string(vehicle_id_);
  if (e.vehicle_id() != vehicle_id_) {
    *error = who + ": an event of vehicle " + std::to_string(e.vehicle_id());
    return false;
  }
  auto push = [&](Action a) {
    if (!actions_.empty() && a.step < actions_.back().step) {
      *error = who + ": an event for step " + std::to_string(a.step) + " after one for step " +
               std::to_string(actions_.back().step) + " (events out of order)";
      return false;
    }
    actions_.push_back(std::move(a));
    return true;
  };
  try {
    if (e.has_spawned() || e.has_checkpoint()) {
      const bool spawned = e.has_spawned();
      const std::uint64_t hash =
          spawned ? e.spawned().terrain_hash() : e.checkpoint().terrain_hash();
      if (hash != terrain_hash_) {
        *error = who + " ran on another terrain" +
                 (spawned ? " ('" + e.spawned().world_name() + "')" : std::string());
        return false;
      }
      Action a;
      a.kind = spawned ? Action::Kind::kSpawned : Action::Kind::kCheckpoint;
      a.step = e.step();
      a.state = FromExactState(spawned ? e.spawned().state() : e.checkpoint().state());
      a.params = std::make_shared<const ValidParams>(
          ParamsFromProto(spawned ? e.spawned().params() : e.checkpoint().params()));
      a.step_ns = spawned ? e.spawned().step_ns() : e.checkpoint().step_ns();
      if (!spawned) a.input = FromInputSample(e.checkpoint().input());
      if (a.step_ns <= 0) {
        *error = who + ": an event with step_ns " + std::to_string(a.step_ns);
        return false;
      }
      return push(std::move(a));
    }
    if (e.has_input_batch()) {
      for (const pb::InputSample& s : e.input_batch().samples()) {
        Action a;
        a.kind = Action::Kind::kInput;
        a.step = s.step();
        a.input = FromInputSample(s);
        if (!push(std::move(a))) return false;
      }
      return true;
    }
    if (e.has_params_changed()) {
      Action a;
      a.kind = Action::Kind::kParams;
      a.step = e.step();
      a.params = std::make_shared<const ValidParams>(ParamsFromProto(e.params_changed().params()));
      return push(std::move(a));
    }
    if (e.has_removed()) {
      Action a;
      a.kind = Action::Kind::kRemoved;
      a.step = e.step();
      return push(std::move(a));
    }
  } catch (const std::exception& ex) {
    *error = who + ", step " + std::to_string(e.step()) + ": " + ex.what();
    return false;
  }
  return true;  // applied requests: what they changed has its own event
}

bool VehicleReplayer::Impl::Apply(const Action& a, std::string* error) {
  switch (a.kind) {
    case Action::Kind::kSpawned:
      if (!sim_) {
        SimConfig c;
        c.step_ns = a.step_ns;
        sim_ = std::make_unique<Simulator>(world_, *a.params, c, a.state);
      }
      sim_->SetParams(*a.params);
      sim_->SetState(a.state);
      return true;
    case Action::Kind::kCheckpoint:
      if (!sim_) {  // a late joiner starts here; a running replay only checks it
        SimConfig c;
        c.step_ns = a.step_ns;
        sim_ = std::make_unique<Simulator>(world_, *a.params, c, a.state);
        sim_->SetInput(a.input);
      }
      return true;
    case Action::Kind::kInput:
      if (sim_) sim_->SetInput(a.input);
      return true;
    case Action::Kind::kParams:
      if (sim_) sim_->SetParams(*a.params);
      return true;
    case Action::Kind::kRemoved:
      sim_.reset();
      return true;
  }
  *error = "unknown action";
  return false;
}

bool VehicleReplayer::Impl::Run(std::uint64_t end_step,
                                const std::function<void(std::uint64_t, std::uint64_t)>& on_step,
                                std::string* error) {
  const std::string who = "vehicle " + std::to_string(vehicle_id_);
  std::size_t& next = next_;
  if (!started_) {
    while (next < actions_.size() && actions_[next].kind != Action::Kind::kSpawned &&
           actions_[next].kind != Action::Kind::kCheckpoint) {
      ++next;
    }
    if (next == actions_.size()) {
      *error = who + ": no spawn or checkpoint event";
      return false;
    }
    started_ = true;
  }
  while (true) {
    const std::uint64_t step =
        sim_ ? static_cast<std::uint64_t>(sim_->state().step) : actions_[next].step;
    // Apply every action that takes effect at this step boundary.
    while (next < actions_.size() && actions_[next].step == step) {
      if (!Apply(actions_[next++], error)) return false;
    }
    if (next < actions_.size() && actions_[next].step < step) {
      *error = who + ": an event for step " + std::to_string(actions_[next].step) +
               " that the replay had already passed (step " + std::to_string(step) + ")";
      return false;
    }
    if (!sim_) {
      // Removed (or not there yet): go on at its next life, if it has one.
      while (next < actions_.size() && actions_[next].kind != Action::Kind::kSpawned) ++next;
      if (next == actions_.size()) break;
      continue;
    }
    if (static_cast<std::uint64_t>(sim_->state().step) >= end_step) break;
    if (const StepStatus status = sim_->Step(); status != StepStatus::kOk) {
      // The recorded session re-spawned the vehicle after this step (its next Spawned event).
      if (next < actions_.size() && actions_[next].kind == Action::Kind::kSpawned) {
        State s = sim_->state();
        s.step = static_cast<std::int64_t>(actions_[next].step);
        sim_->SetState(s);
        continue;
      }
      *error = who + ": the re-simulation discarded step " + std::to_string(step) + " (" +
               StepStatusText(status) +
               ") where the recorded session went on: a recording made before that check?";
      return false;
    }
    if (on_step) on_step(step, sim_->last_step().hash_after);
  }
  return true;
}

ResimResult Resimulate(std::shared_ptr<const World> world,
                       const std::vector<pb::SessionEvent>& events_in,
                       const std::map<std::uint32_t, std::uint64_t>& end_step) {
  ResimResult out;
  const std::uint64_t terrain_hash = TerrainHash(world->terrain);
  // DDS delivers a keyed topic instance by instance; the server's sequence is the true order.
  std::vector<const pb::SessionEvent*> events;
  events.reserve(events_in.size());
  for (const auto& e : events_in) events.push_back(&e);
  std::stable_sort(events.begin(), events.end(),
                   [](const auto* a, const auto* b) { return a->sequence() < b->sequence(); });
  for (std::size_t i = 1; i < events.size(); ++i) {
    if (events[i]->sequence() != events[i - 1]->sequence() + 1) {
      out.ok = false;
      out.error = "event sequence has a gap after " + std::to_string(events[i - 1]->sequence());
      return out;
    }
  }
  for (const auto& [vehicle, end] : end_step) {
    VehicleReplayer replayer(world, terrain_hash, vehicle);
    for (const pb::SessionEvent* e : events) {
      if (e->vehicle_id() != vehicle) continue;
      if (!replayer.Add(*e, &out.error)) {
        out.ok = false;
        return out;
      }
    }
    auto& hashes = out.hashes[vehicle];
    if (!replayer.Run(
            end, [&](std::uint64_t step, std::uint64_t h) { hashes[step] = h; }, &out.error)) {
      out.ok = false;
      return out;
    }
  }
  return out;
}

}  // namespace vdyn
