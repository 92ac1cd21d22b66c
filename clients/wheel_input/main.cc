// vdyn-input: sends driver input for one vehicle over DDS.
//
// Source so far: a maneuver (CSV file or the built-in demo), played against the server's
// simulation time (taken from the vehicle's state topic) or against the wall clock. Input is
// written at a fixed rate even when it does not change: the server's watchdog and the input
// topic's deadline expect a live writer. Exit codes: 0 done, 2 bad input, 1 transport failure.
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <thread>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include "vdyn/base/time.h"
#include "vdyn/cli/options.h"
#include "vdyn/client/driver_input.h"
#include "vdyn/client/loop.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/input.pb.h"
#include "vdyn/state.pb.h"

namespace {

std::atomic<bool> g_stop{false};
extern "C" void OnSignal(int) { g_stop.store(true); }

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"vdyn-input: driver input for a vdyn vehicle over DDS"};
  std::string maneuver_name;
  std::uint32_t domain = 0, vehicle_id = 1;
  std::string source_id = "vdyn-input";
  std::int32_t strength = 10;
  double rate_hz = 500.0;
  std::string clock = "server";
  double wait_s = 10.0;
  bool loop = false;
  app.add_option("--maneuver", maneuver_name, "Maneuver CSV to play, or 'demo'")->required();
  app.add_option("--domain", domain, "DDS domain id")
      ->check(vdyn::cli::WholeInRange(vdyn::limits::kDomainId))
      ->capture_default_str();
  app.add_option("--vehicle-id", vehicle_id, "Vehicle to drive")->capture_default_str();
  app.add_option("--source-id", source_id, "This source's name (shown in the state)")
      ->capture_default_str();
  app.add_option("--strength", strength,
                 "Ownership strength: the strongest live source drives (primary rig > backup)")
      ->capture_default_str();
  app.add_option("--rate-hz", rate_hz, "Input messages per second")
      ->check(vdyn::cli::InRange(vdyn::limits::kRateHz))
      ->capture_default_str();
  app.add_option("--clock", clock,
                 "Maneuver time: 'server' (the vehicle's simulation time) or 'wall'")
      ->check(CLI::IsMember({"server", "wall"}))
      ->capture_default_str();
  app.add_option("--wait", wait_s, "Seconds to wait for the server's first state (clock=server)")
      ->check(vdyn::cli::InRange(vdyn::limits::kWaitS))
      ->capture_default_str();
  app.add_flag("--loop", loop, "Start the maneuver again at its end");
  if (const int code = vdyn::cli::Parse(app, argc, argv); code >= 0) return code;

  try {
    const vdyn::Maneuver maneuver = vdyn::Maneuver::Named(maneuver_name);
    std::signal(SIGINT, OnSignal);
    std::signal(SIGTERM, OnSignal);
    vdyn::transport::DropCounters drops;
    vdyn::transport::Participant participant(domain);
    vdyn::client::InputPublisher writer(participant, vehicle_id, source_id, strength);
    vdyn::transport::Reader<vdyn::pb::VehicleState> states(
        participant, vdyn::transport::TopicId::kState, &drops);

    // Simulation time of the vehicle, from its newest state (clock=server).
    std::int64_t sim_ns = -1;
    auto poll_states = [&] {
      states.Take([&](const vdyn::pb::VehicleState& s, const vdyn::transport::SampleInfo&) {
        if (s.vehicle_id() == vehicle_id) sim_ns = s.sim_time_ns();
      });
    };
    if (clock == "server") {
      const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(wait_s);
      while (sim_ns < 0 && !g_stop && std::chrono::steady_clock::now() < deadline) {
        states.Wait(std::chrono::milliseconds(50));
        poll_states();
      }
      if (sim_ns < 0) {
        std::cerr << "vdyn-input: no state of vehicle " << vehicle_id << " on domain " << domain
                  << " within " << wait_s << " s; is vdyn-server running?\n";
        return 1;
      }
    }
    spdlog::info("vdyn-input: playing '{}' ({:.1f} s) for vehicle {} as '{}' (strength {})",
                 maneuver_name, maneuver.end_time(), vehicle_id, source_id, strength);

    const vdyn::base::MonoTime wall_start = vdyn::base::MonotonicNow();
    const std::int64_t sim_start = sim_ns;
    vdyn::client::FixedRateLoop loop_clock(
        vdyn::base::Nanos{static_cast<std::int64_t>(1e9 / rate_hz)}, wall_start);
    vdyn::pb::DriverInput msg;
    while (!g_stop) {
      const auto tick = loop_clock.Wait();
      double t = 0.0;
      if (clock == "server") {
        poll_states();
        t = static_cast<double>(sim_ns - sim_start) * 1e-9;
      } else {
        t = (tick.now - wall_start).seconds();
      }
      if (t > maneuver.end_time()) {
        if (!loop) break;
        t = std::fmod(t, maneuver.end_time());
      }
      vdyn::client::FillFromManeuver(maneuver.At(t), msg);
      if (!writer.Publish(msg)) {
        std::cerr << "vdyn-input: " << writer.last_error() << "\n";
        return 1;
      }
    }
    return 0;
  } catch (const vdyn::ManeuverError& e) {
    std::cerr << "vdyn-input: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "vdyn-input: " << e.what() << "\n";
    return 1;
  }
}
