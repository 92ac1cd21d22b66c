// What a client sees of a domain: the newest state of every vehicle, its parameters (from the
// transient-local topic: at once for a late joiner), each server's world and diagnostics, and
// optionally the driver inputs (paddle presses for the viewer's north camera). Poll() takes what
// has arrived; call it from one thread (a client's loop or a render frame).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "vdyn/base/time.h"
#include "vdyn/client/state_reader.h"
#include "vdyn/diagnostics.pb.h"
#include "vdyn/input.pb.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"
#include "vdyn/vehicle_params.pb.h"
#include "vdyn/world.pb.h"

namespace vdyn::client {

class SessionView {
 public:
  struct Topics {
    bool states = true;
    bool params = true;
    bool world = true;
    bool diagnostics = true;
    bool inputs = false;
    // States of this vehicle only, read in its partition (transport::VehiclePartition): the
    // other vehicles' states are not sent here at all, so a client that follows one vehicle pays
    // for one whatever the number of vehicles. Without it, every vehicle's states.
    std::optional<std::uint32_t> only_vehicle;
    // States of this server only (empty: every server's on the domain).
    std::string only_server;
  };
  struct Vehicle {
    pb::VehicleState state;                 // the newest
    base::MonoTime received;                // when it was taken here
    std::int64_t source_timestamp_ns = 0;   // the server's wall clock when it wrote it
    std::uint64_t states = 0;               // states received
    std::optional<pb::VehicleParams> params;
    std::optional<pb::DriverInput> input;   // the newest driver input seen (Topics::inputs)
  };

  SessionView(transport::Participant& participant, Topics topics);
  SessionView(const SessionView&) = delete;
  SessionView& operator=(const SessionView&) = delete;

  // Takes every sample that has arrived; returns how many.
  int Poll();
  // Waits up to `timeout` for a state (or, without states, anything) to arrive.
  [[nodiscard]] bool Wait(std::chrono::nanoseconds timeout);

  // Called by Poll() for every state, as it is taken (e.g. force feedback's lowest latency path).
  std::function<void(const pb::VehicleState&, const transport::SampleInfo&)> on_state;
  // Called by Poll() for every driver input (Topics::inputs).
  std::function<void(const pb::DriverInput&, const transport::SampleInfo&)> on_input;
  // Called by Poll() for every world description as it arrives, before it is stored (a viewer
  // checks it and counts one it cannot draw).
  std::function<void(const pb::WorldDescription&, const transport::SampleInfo&)> on_world;

  const std::map<std::uint32_t, Vehicle>& vehicles() const { return vehicles_; }
  const Vehicle* vehicle(std::uint32_t id) const;
  // Forgets a vehicle that has left (its server no longer runs it): it is seen again only when a
  // new state of it arrives.
  void Forget(std::uint32_t id) { vehicles_.erase(id); }
  // Worlds and diagnostics by server id.
  const std::map<std::string, pb::WorldDescription>& worlds() const { return worlds_; }
  const std::map<std::string, pb::Diagnostics>& diagnostics() const { return diagnostics_; }
  // Increases each time a world arrives (a viewer rebuilds its meshes when it changes).
  std::uint64_t world_version() const { return world_version_; }
  transport::DropCounters& drops() { return drops_; }
  // With Topics::only_vehicle: empty when the states are read in the vehicle's partition; else
  // why that reader could not be created (e.g. DDS Security permissions without the partition),
  // and every vehicle's states are read and the others' dropped here.
  const std::string& one_vehicle_fallback() const;

 private:
  void OnState(const pb::VehicleState& s, const transport::SampleInfo& info);

  transport::DropCounters drops_;
  std::unique_ptr<StateReader> states_;
  std::string only_server_;
  std::unique_ptr<transport::Reader<pb::VehicleParams>> params_;
  std::unique_ptr<transport::Reader<pb::WorldDescription>> world_;
  std::unique_ptr<transport::Reader<pb::Diagnostics>> diagnostics_reader_;
  std::unique_ptr<transport::Reader<pb::DriverInput>> inputs_;
  std::unique_ptr<transport::Waitset> waitset_;
  std::map<std::uint32_t, Vehicle> vehicles_;
  std::map<std::string, pb::WorldDescription> worlds_;
  std::map<std::string, pb::Diagnostics> diagnostics_;
  std::uint64_t world_version_ = 0;
};

}  // namespace vdyn::client
