// Conversions between the core's types and the Protocol Buffers messages of proto/.
#pragma once

#include <string>

#include "simulator.h"
#include "vdyn/input.pb.h"
#include "vdyn/session.pb.h"
#include "vdyn/state.pb.h"
#include "vdyn/world.pb.h"
#include "world.h"

namespace vdyn {

DriverInput FromProto(const pb::DriverInput& in);
// Fills the physics fields of `out` (steer, throttle, brake, cruise); leaves the rest.
void ToProto(const DriverInput& in, pb::DriverInput& out);

pb::ExactState ToExactState(const State& s);
// Throws std::invalid_argument when the message does not hold a complete, finite state.
State FromExactState(const pb::ExactState& m);

// The state message of one step: the record of the step (state at its start, derived
// quantities, controls), the input message that was latched for it and the hash after it.
// `sim_time_ns` is the server's simulation time at the step's start (the same clock for every
// vehicle); the record's step is the vehicle's own.
void FillVehicleState(std::uint32_t vehicle_id, const std::string& server_id,
                      std::int64_t step_ns, std::int64_t sim_time_ns, const StepRecord& r,
                      const pb::DriverInput& input, bool watchdog_safe_state,
                      double steering_torque, pb::VehicleState& out);

// FNV-1a-64 over every mesh's vertices and indices (a re-simulation checks it).
std::uint64_t TerrainHash(const Terrain& terrain);

// The world description a viewer needs: meshes, landmarks, north, spawn.
pb::WorldDescription DescribeWorld(const World& world, const std::string& server_id,
                                   std::int64_t step_ns);

pb::VehicleGeometry DescribeVehicle(std::uint32_t vehicle_id, const Params& p);

}  // namespace vdyn
