#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>

#include <spdlog/spdlog.h>

#include "command_support.h"
#include "vdyn/base/deadline.h"
#include "vdyn/base/text.h"
#include "vdyn/client/driver_input.h"
#include "vdyn/client/loop.h"
#include "vdyn/client/session_view.h"
#include "vdyn/input.pb.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/state.pb.h"
#include "vdyn/wheel_input/commands.h"

namespace vdyn::wheel_input {
namespace {

using base::MonoTime;
using base::MonotonicNow;

// The vehicles the servers on the domain publish, by their parameters (kept for late joiners:
// they arrive soon after the reader matches, not always together), gathered for 1 s; empty where
// no server runs.
std::vector<std::uint32_t> VehiclesOnDomain(transport::Participant& participant) {
  client::SessionView view(participant, {.states = false,
                                         .params = true,
                                         .world = false,
                                         .diagnostics = false,
                                         .inputs = false,
                                         .only_vehicle = std::nullopt, .only_server = {}});
  (void)base::PollUntil(
      base::Deadline::After(base::Seconds(1)), base::Milliseconds(100),
      [&] {
        view.Poll();
        return false;  // all that come within the second
      },
      [&](base::Nanos slice) { (void)view.Wait(base::Chrono(slice)); });
  std::vector<std::uint32_t> ids;
  for (const auto& [id, vehicle] : view.vehicles()) ids.push_back(id);
  return ids;
}

// A server publishes a state every step (1 kHz): this long without one, none is running (or it
// is paused).
constexpr double kSilentS = 2.0;

}  // namespace

int Play(const CommonOptions& c, const PlayOptions& o, const std::atomic<bool>& stop) {
  const Maneuver maneuver = Maneuver::Named(o.maneuver);
  transport::Participant participant(c.domain);
  client::InputPublisher writer(participant, c.vehicle_id, c.source_id, c.strength);
  // This vehicle's states only (its partition): the others' are not sent here.
  client::SessionView states(participant, {.states = true,
                                           .params = false,
                                           .world = false,
                                           .diagnostics = false,
                                           .inputs = false,
                                           .only_vehicle = c.vehicle_id, .only_server = {}});
  if (!states.one_vehicle_fallback().empty()) {
    spdlog::warn("vdyn-input: reading every vehicle's states ({})", states.one_vehicle_fallback());
  }
  const bool server_clock = o.clock == "server";

  // The vehicle's newest simulation time (clock=server) and what its states say about this input.
  std::int64_t sim_ns = -1;
  std::uint64_t states_seen = 0, states_ours = 0;
  // Times the server's watchdog took the vehicle from this input (a state of ours, then one in
  // the watchdog's safe state): this input arrived too late (issue 31, bench/input_starvation.sh).
  std::uint64_t watchdog_takeovers = 0;
  bool was_ours = false;
  std::string other_source;  // the newest other source that drove the vehicle
  MonoTime last_state_at{};
  states.on_state = [&](const pb::VehicleState& s, const transport::SampleInfo&) {
    if (s.vehicle_id() != c.vehicle_id) return;
    sim_ns = s.sim_time_ns();
    ++states_seen;
    last_state_at = MonotonicNow();
    if (was_ours && s.control().watchdog_safe_state()) ++watchdog_takeovers;
    was_ours = s.input().source_id() == c.source_id;
    if (was_ours) {
      ++states_ours;
    } else if (!s.input().source_id().empty()) {
      other_source = s.input().source_id();
    }
  };
  auto poll_states = [&] { states.Poll(); };
  const std::string where =
      "vehicle " + std::to_string(c.vehicle_id) + " on domain " + std::to_string(c.domain);
  if (server_clock) {
    spdlog::info("vdyn-input: waiting up to {} s for a state of {}", c.wait_s, where);
    (void)base::PollUntil(
        base::Deadline::AfterSeconds(c.wait_s), base::Milliseconds(50),
        [&] {
          poll_states();
          return sim_ns >= 0 || stop;
        },
        [&](base::Nanos slice) { (void)states.Wait(base::Chrono(slice)); });
    if (stop) return 0;
    if (sim_ns < 0) {
      std::cerr << "vdyn-input: no state of " << where << " within " << c.wait_s << " s; "
                << WhyNoVehicle(c, VehiclesOnDomain(participant)) << "\n";
      return 1;
    }
  }
  spdlog::info(
      "vdyn-input: playing '{}' ({:.1f} s, {} clock) for vehicle {} as '{}' (strength {}); {}",
      o.maneuver, maneuver.end_time(), o.clock, c.vehicle_id, c.source_id, c.strength,
      SetUpLoopScheduling(c));

  const MonoTime wall_start = MonotonicNow();
  const std::int64_t sim_start = sim_ns;
  client::FixedRateLoop loop_clock(LoopPeriod(c.rate_hz), wall_start);
  pb::DriverInput msg;
  bool warned_silent = false;
  double t = 0.0;
  while (!stop) {
    const auto tick = loop_clock.Wait();
    poll_states();
    // Silence: no server yet, or it went away or paused. The wall clock plays on; the server's
    // clock stands still without states, and the maneuver with it. Either way, it is said.
    const double silent_s = (tick.now - (states_seen > 0 ? last_state_at : wall_start)).seconds();
    if (silent_s >= kSilentS && !warned_silent) {
      warned_silent = true;
      if (states_seen == 0) {
        spdlog::warn(
            "vdyn-input: no state of {} after {:.0f} s of playing; is vdyn-server "
            "running? The maneuver plays on by the wall clock, heard by no one",
            where, kSilentS);
      } else {
        spdlog::warn(
            "vdyn-input: no state of {} for {:.0f} s, at {:.1f} s of the maneuver: "
            "vdyn-server is paused or has stopped; {}",
            where, kSilentS, t,
            server_clock ? "the maneuver waits for its clock"
                         : "the maneuver plays on by the wall clock");
      }
    } else if (silent_s < kSilentS && warned_silent) {
      warned_silent = false;
      spdlog::info("vdyn-input: states of {} again", where);
    }
    if (server_clock) {
      t = static_cast<double>(sim_ns - sim_start) * 1e-9;
    } else {
      t = (tick.now - wall_start).seconds();
    }
    if (t > maneuver.end_time()) {
      if (!o.loop) break;
      t = std::fmod(t, maneuver.end_time());
    }
    client::FillFromManeuver(maneuver.At(t), msg);
    if (!writer.Publish(msg)) {
      std::cerr << "vdyn-input: " << writer.last_error() << "\n";
      return 1;
    }
  }
  // The outcome: whether a server took the input.
  const std::string played =
      stop ? "stopped at " + base::FormatFixed(t, 1) + " s of '" + o.maneuver + "'"
           : "played '" + o.maneuver + "' to its end (" +
                 base::FormatFixed(maneuver.end_time(), 1) + " s, " + o.clock + " clock)";
  if (states_seen == 0) {
    std::cerr << "vdyn-input: " << played << ", but no server took it: no state of " << where
              << " arrived; " << WhyNoVehicle(c, VehiclesOnDomain(participant)) << "\n";
    return stop ? 0 : 1;
  }
  std::string outcome = "vdyn-input: " + played + "; " + std::to_string(states_ours) + " of " +
                        std::to_string(states_seen) + " states of vehicle " +
                        std::to_string(c.vehicle_id) + " applied this input; watchdog took over " +
                        std::to_string(watchdog_takeovers) + " times";
  if (states_ours == 0 && !other_source.empty()) {
    outcome += " ('" + other_source + "' drove it: a stronger source than --strength " +
               std::to_string(c.strength) + ")";
  }
  std::printf("%s\n", outcome.c_str());
  return 0;
}

}  // namespace vdyn::wheel_input
