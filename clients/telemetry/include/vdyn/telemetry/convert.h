// Vehicle states to OutSim and OutGauge packets (docs/formats.md, "UDP telemetry").
//
// Frames: LFS's world has X and Y on the ground and Z up, right-handed, with a heading of 0 when
// the car's forward axis points along +Y, growing anticlockwise seen from above. vdyn's world W
// (docs/model.md) is X east, Y north, Z up, with yaw 0 along +X. So vectors in W are sent as they
// are (X east, Y north, Z up), and heading = yaw - pi/2, wrapped into [-pi, pi). LFS's car axes
// are X right, Y forward, Z up: its pitch (about X, anticlockwise seen from the right) is nose up
// positive = -theta, and its roll (about Y, anticlockwise seen from the front) is right side down
// positive = phi, with vdyn's R_WB = Rz(psi) Ry(theta) Rx(phi) (heading, then pitch, then roll).
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "vdyn/state.pb.h"
#include "vdyn/telemetry/packets.h"
#include "vdyn/vehicle_params.pb.h"

namespace vdyn::telemetry {

// LFS heading from vdyn's yaw (rad), in [-pi, pi).
double HeadingFromYaw(double yaw_rad);
// Metres to LFS position units (1 m = 65536), rounded, saturated to the int32 range (+-32768 m).
std::int32_t PositionUnits(double m);
// Simulation time to the packets' Time, ms (modulo 2^32: it wraps after 49.7 days).
std::uint32_t TimeMs(std::int64_t sim_time_ns);

// OutSim from a state: time, angular velocity, heading/pitch/roll, acceleration, velocity and
// position of the centre of gravity, all in world axes.
OutSimPack MakeOutSim(const pb::VehicleState& s, std::int32_t id = 0);

struct GaugeOptions {
  std::string car = "VDYN";  // Car[4]
  std::int32_t id = 0;
};

// OutGauge gear from a state: the full model's engaged gear (-1 R, 0 N, 1..N) as 0, 1, 2..; the
// paper's model has no gearbox (one fixed drive ratio, a negative throttle drives backwards), so
// it reads reverse while the applied throttle is negative, else first.
std::uint8_t GaugeGear(const pb::VehicleState& s);

// OutGauge from a state and, when known, the vehicle's parameters (which lights the car has:
// ABS, traction control, the shift light at shift_up_rpm).
OutGaugePack MakeOutGauge(const pb::VehicleState& s, const pb::VehicleParams* params,
                          const GaugeOptions& o);

}  // namespace vdyn::telemetry
