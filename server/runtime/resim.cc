#include "resim.h"

#include <algorithm>

#include "convert.h"
#include "params_io.h"
#include "simulator.h"

namespace vdyn {

ResimResult Resimulate(std::shared_ptr<const World> world,
                       const std::vector<pb::SessionEvent>& events_in,
                       const std::map<std::uint32_t, std::uint64_t>& end_step) {
  ResimResult out;
  const std::uint64_t terrain_hash = TerrainHash(world->terrain);
  // DDS delivers a keyed topic instance by instance; the server's sequence is the true order.
  std::vector<pb::SessionEvent> events = events_in;
  std::stable_sort(events.begin(), events.end(),
                   [](const auto& a, const auto& b) { return a.sequence() < b.sequence(); });
  for (std::size_t i = 1; i < events.size(); ++i) {
    if (events[i].sequence() != events[i - 1].sequence() + 1) {
      out.ok = false;
      out.error = "event sequence has a gap after " + std::to_string(events[i - 1].sequence());
      return out;
    }
  }
  for (const auto& [vehicle, end] : end_step) {
    // This vehicle's events, in order.
    std::vector<const pb::SessionEvent*> mine;
    for (const auto& e : events) {
      if (e.vehicle_id() == vehicle) mine.push_back(&e);
    }
    std::size_t next = 0;
    while (next < mine.size() && !mine[next]->has_spawned() && !mine[next]->has_checkpoint()) {
      ++next;
    }
    if (next == mine.size()) {
      out.ok = false;
      out.error = "vehicle " + std::to_string(vehicle) + ": no spawn or checkpoint event";
      return out;
    }
    std::unique_ptr<Simulator> sim;
    std::int64_t step_ns = 0;
    auto& hashes = out.hashes[vehicle];
    while (true) {
      const std::uint64_t step = sim ? static_cast<std::uint64_t>(sim->state().step)
                                     : mine[next]->step();
      // Apply every event that takes effect at this step boundary.
      while (next < mine.size() && mine[next]->step() == step) {
        const pb::SessionEvent& e = *mine[next++];
        try {
          if (e.has_spawned()) {
            if (e.spawned().terrain_hash() != terrain_hash) {
              out.ok = false;
              out.error = "vehicle " + std::to_string(vehicle) + " ran on another terrain ('" +
                          e.spawned().world_name() + "')";
              return out;
            }
            step_ns = e.spawned().step_ns();
            const Params p = ParamsFromProto(e.spawned().params());
            const State st = FromExactState(e.spawned().state());
            if (!sim) {
              SimConfig c;
              c.step_ns = step_ns;
              sim = std::make_unique<Simulator>(world, p, c, st);
            }
            sim->SetParams(p);
            sim->SetState(st);
          } else if (e.has_checkpoint()) {
            if (!sim) {
              if (e.checkpoint().terrain_hash() != terrain_hash) {
                out.ok = false;
                out.error = "vehicle " + std::to_string(vehicle) + " ran on another terrain";
                return out;
              }
              step_ns = e.checkpoint().step_ns();
              SimConfig c;
              c.step_ns = step_ns;
              sim = std::make_unique<Simulator>(world, ParamsFromProto(e.checkpoint().params()), c,
                                                FromExactState(e.checkpoint().state()));
              sim->SetInput(FromProto(e.checkpoint().input()));
            }
          } else if (e.has_input_changed() && sim) {
            sim->SetInput(FromProto(e.input_changed().input()));
          } else if (e.has_params_changed() && sim) {
            sim->SetParams(ParamsFromProto(e.params_changed().params()));
          } else if (e.has_removed()) {
            sim.reset();
          }
        } catch (const std::exception& ex) {
          out.ok = false;
          out.error = "vehicle " + std::to_string(vehicle) + ", step " + std::to_string(step) +
                      ": " + ex.what();
          return out;
        }
      }
      if (!sim) {
        // Removed (or not there yet): go on at its next life, if it has one.
        while (next < mine.size() && !mine[next]->has_spawned()) ++next;
        if (next == mine.size()) break;
        continue;
      }
      if (static_cast<std::uint64_t>(sim->state().step) >= end) break;
      if (sim->Step() != StepStatus::kOk) {
        // The recorded session re-spawned the vehicle after this step (its next Spawned event).
        if (next < mine.size() && mine[next]->has_spawned()) {
          State s = sim->state();
          s.step = static_cast<std::int64_t>(mine[next]->step());
          sim->SetState(s);
          continue;
        }
        out.ok = false;
        out.error = "vehicle " + std::to_string(vehicle) + ": non-finite state at step " +
                    std::to_string(step);
        return out;
      }
      hashes[step] = sim->last_step().hash_after;
    }
  }
  return out;
}

}  // namespace vdyn
