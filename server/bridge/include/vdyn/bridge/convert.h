// Conversions between the physics' types and the Protocol Buffers messages of proto/ (and the
// maneuver rows of io/): the bridge where messages and files meet the physics.
#pragma once

#include <memory>
#include <string>

#include "vdyn/input.pb.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/physics/world.h"
#include "vdyn/session.pb.h"
#include "vdyn/state.pb.h"
#include "vdyn/world.pb.h"

namespace vdyn {

DriverInput FromProto(const pb::DriverInput& in);
// Fills the physics fields of `out` (steer, throttle, brake, cruise); leaves the rest.
void ToProto(const DriverInput& in, pb::DriverInput& out);
DriverInput FromManeuver(const ManeuverInput& in);

// The exact input of an event (SI, bit for bit) and back.
void ToInputSample(const DriverInput& in, std::int64_t step, pb::InputSample& out);
DriverInput FromInputSample(const pb::InputSample& s);

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

// The terrain hash (docs/hash.md): vdyn-hash64 over every mesh, in order, of its vertices'
// coordinates (x, y, z as doubles) and then its triangles' indices (as integers). The same from a
// world description's meshes, so a recording can be checked against the world it was made on.
std::uint64_t TerrainHash(const Terrain& terrain);
std::uint64_t TerrainHash(const pb::WorldDescription& world);

// A world rebuilt from its description (a recorder's re-simulation). Throws WorldError for a
// description whose meshes are malformed (an index out of range, a vertex count not a multiple
// of 3) or that holds no usable triangle.
std::unique_ptr<World> WorldFromDescription(const pb::WorldDescription& d);

// The world description a viewer needs: meshes, landmarks, north, spawn.
pb::WorldDescription DescribeWorld(const World& world, const std::string& server_id,
                                   std::int64_t step_ns);

pb::VehicleGeometry DescribeVehicle(std::uint32_t vehicle_id, const Params& p);

}  // namespace vdyn
