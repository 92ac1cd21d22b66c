// A vdyn session as Foxglove's 3D panel shows it, built from the state and world messages alone
// (no physics): what vdyn-foxglove sends live and `vdyn-recorder export --foxglove` writes into a
// copy of a recording, so both show the same scene.
//
//   frames      world -> vehicle/<id>/body (the centre of gravity T, orientation q_WB)
//                     -> vehicle/<id>/wheel/LF|RF|LR|RR (the wheel's centre, turned by its
//                        steering angle about the body's Z) foxglove.FrameTransforms
//   entities    vehicle/<id>/body: the body as boxes in its colour, its id above the roof
//               vehicle/<id>/wheel/LF..RR: each wheel a cylinder in its wheel frame
//               vehicle/<id>/forces: the force arrows of the paper's Fig. 3 in the world frame,
//               the viewer's colours and scale (clients/vr_viewer/README.md): per wheel at the
//               contact point B spring Fp (along the terrain normal), drive Fh and brake Fb
//               (along the wheel's heading in the ground plane; the full model: the tire's Fx,
//               drive where it pushes, brake where it holds back), side Fy (across it); drag
//               ending at the nose, the wall force from above the roof foxglove.SceneUpdate
//   world       world/<server id>: each terrain mesh as a triangle list coloured by its surface
//               kind, the landmarks as labels foxglove.SceneUpdate
//
// The builders fill messages the caller keeps and reuses; a state must pass CheckState first.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include "vdyn/client/palette.h"
#include "vdyn/state.pb.h"
#include "vdyn/vehicle_params.pb.h"
#include "vdyn/world.pb.h"

namespace foxglove {
class FrameTransforms;
class SceneUpdate;
}  // namespace foxglove

namespace vdyn::foxglove {

inline constexpr int kWheels = 4;  // LF, RF, LR, RR

using client::ForceKind;  // the arrows' kinds, names and colours: client/palette.h
using client::ForceLabel;   // "spring Fp"
using client::WheelName;    // "LF"
inline constexpr int kArrowsPerVehicle = 4 * kWheels + 2;

struct Rgb8 {
  std::uint8_t r = 0, g = 0, b = 0;
};
// The viewer's legend (client/palette.h): spring green, drive blue, brake red, side yellow, drag
// magenta, wall orange.
Rgb8 ForceColour(ForceKind kind);
// A vehicle's colour by id: the viewer's palette.
Rgb8 VehicleColour(std::uint32_t vehicle_id);

struct Vec3 {
  double x = 0, y = 0, z = 0;
};

// What the scene needs of a vehicle's build: mount points A in the body frame (m), wheel radii,
// free spring lengths, the body box from T (front, rear, half width).
struct Geometry {
  std::array<Vec3, kWheels> mount_B{};
  std::array<double, kWheels> radius{};
  std::array<double, kWheels> free_length{};
  double front = 2.2, rear = 2.5, half_width = 0.9;
};
// From the server's world description of the vehicle, else from its parameters, else a mid-size
// car's (the server's defaults) - as the viewer chooses.
Geometry GeometryFor(std::uint32_t vehicle_id, const pb::WorldDescription* world,
                     const pb::VehicleParams* params);

// Empty when a state can be drawn: four wheels, a usable quaternion, positions within 1e7 m;
// else why not.
std::string CheckState(const pb::VehicleState& s);

struct SceneOptions {
  double arrow_m_per_kn = 0.5;  // the viewer's --arrow-scale default
};

std::string BodyFrame(std::uint32_t vehicle_id);              // "vehicle/1/body"
std::string WheelFrame(std::uint32_t vehicle_id, int wheel);  // "vehicle/1/wheel/LF"
inline constexpr const char* kWorldFrame = "world";

// A force arrow as the scene draws it: where it starts and what it is (N, world frame).
struct Arrow {
  ForceKind kind = ForceKind::kSpring;
  int wheel = -1;  // 0..3, or -1 for a force on the body
  Vec3 tail_W;
  Vec3 force_W;
};
// Every arrow of a state, in the order the forces entity lists them: per wheel LF..RR spring,
// drive, brake, side; then drag, wall.
std::array<Arrow, kArrowsPerVehicle> ForceArrows(const pb::VehicleState& s, const Geometry& g,
                                                 const SceneOptions& o);

// `stamp_ns` goes into every timestamp (the simulation clock live, the recording's log time in
// an export).
void BuildTransforms(const pb::VehicleState& s, const Geometry& g, std::int64_t stamp_ns,
                     ::foxglove::FrameTransforms& out);
void BuildVehicleScene(const pb::VehicleState& s, const Geometry& g, const SceneOptions& o,
                       std::int64_t stamp_ns, ::foxglove::SceneUpdate& out);
void BuildWorldScene(const pb::WorldDescription& w, std::int64_t stamp_ns,
                     ::foxglove::SceneUpdate& out);

}  // namespace vdyn::foxglove
