// What the viewer draws of a vehicle, computed from its state message alone (no physics): the
// body's pose, each wheel at its spring position and steering angle, and the force arrows of the
// paper's Fig. 3 - per wheel at the contact point B the spring force Fp (along the terrain normal),
// the drive force Fh and brake force Fb (along the wheel's heading in the ground plane) and the
// side force Fy (across it), and at the body the aerodynamic drag and the wall force.
//
// The directions follow the model (docs/model.md): a wheel's heading is cos(gamma) X_B +
// sin(gamma) Y_B projected on the ground plane (t_long), t_lat = n x t_long; Fb opposes the
// wheel's rolling; drag is -Da X_B. The sum of a wheel's arrows (with rolling resistance) is the
// wheel force f_w the server reports (tests check it against a live server).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "vdyn/client/palette.h"
#include "vdyn/state.pb.h"
#include "vdyn/vehicle_params.pb.h"
#include "vdyn/viewer/math.h"
#include "vdyn/world.pb.h"

namespace vdyn::viewer {

inline constexpr int kWheels = 4;  // LF, RF, LR, RR

using client::ForceKind;  // the arrows' kinds, names and colours: client/palette.h
using client::ForceLabel;   // "spring Fp"
using client::kForceKinds;
using client::WheelName;  // "LF"

struct Rgb8 {
  std::uint8_t r = 0, g = 0, b = 0;
};
// The legend: spring green, drive blue, brake red, side yellow, drag magenta, wall orange. Arrows
// are drawn unlit, in exactly these colours.
Rgb8 ForceColour(ForceKind kind);

// A vehicle's colour by id (a palette of eight that avoids the arrows' hues).
Rgb8 VehicleColour(std::uint32_t vehicle_id);

struct VehicleGeometry {
  std::array<Vec3, kWheels> mount_B{};   // mount points A from T, body frame, m
  std::array<double, kWheels> radius{};  // m
  std::array<double, kWheels> free_length{};
  double front = 2.2, rear = 2.5, half_width = 0.9;  // body box from T, m
  // For the cockpit (its parameters when known): the hand wheel turns steering_ratio times the
  // road wheels (the paper model publishes no hand-wheel angle); the rev limiter's speed.
  double steering_ratio = 15;
  double engine_rpm_limit = 6500;
  enum class Source { kWorld, kParams, kDefault };
  Source source = Source::kDefault;
};
// The vehicle's geometry from its server's world description, else from its parameters (the
// transient-local topic), else a mid-size car's.
VehicleGeometry GeometryFor(std::uint32_t vehicle_id, const pb::WorldDescription* world,
                            const pb::VehicleParams* params);
// Empty when the world's description of a vehicle is usable, else why not.
std::string CheckGeometry(const pb::VehicleGeometry& g);

struct WheelView {
  Vec3 mount_W;    // A
  Vec3 contact_W;  // B (the hanging wheel's bottom when in the air)
  Vec3 centre_W;   // the wheel's centre: one radius from B towards A
  Vec3 forward_W;  // the steered wheel's frame: forward, left (the axle), up
  Vec3 left_W;
  Vec3 up_W;
  Vec3 n_W;       // terrain normal at B
  Vec3 t_long_W;  // the wheel's heading in the ground plane
  Vec3 t_lat_W;   // n x t_long
  double radius = 0.3;
  bool contact = false;
  // The wheel's turn about its axle, rad (positive rolling forward): its rim and the marks on its
  // tyre are drawn turned by it (WheelSpin).
  double spin = 0;
};

struct ForceArrow {
  ForceKind kind = ForceKind::kSpring;
  int wheel = -1;  // 0..3, or -1 for a force on the body
  Vec3 anchor_W;   // where the force acts (B, or a point on the body)
  Vec3 force_W;    // N
  // Drawn ending at the anchor (drag: the air pushes on the nose) instead of starting there.
  bool tip_at_anchor = false;
};

struct VehicleView {
  std::uint32_t id = 0;
  std::uint64_t step = 0;  // the state's step
  Pose pose_WB;            // body frame at T
  VehicleGeometry geometry;
  std::array<WheelView, kWheels> wheels{};
  std::vector<ForceArrow> arrows;  // every force, zero ones included (drawn when long enough)
  double speed_kmh = 0;
  // Heading of the body's X axis in the ground plane, rad from +X_W towards +Y_W.
  double yaw = 0;
  // Ground height under the vehicle (mean of the four B), m.
  double ground_z = 0;
  // Its lamps: the brake lights while it brakes (the applied brake input, or a brake torque at
  // a wheel, over the thresholds below), the reversing lights in reverse gear or while the drive
  // pushes it backwards.
  bool braking = false;
  bool reversing = false;
  // The cockpit's readings: the hand wheel's angle (rad, positive left: the full model's
  // steering state, else the road wheels' steering angle times the steering ratio), the engine's
  // speed and the engaged gear (-1 reverse, 0 neutral; the full model only).
  double hand_wheel_rad = 0;
  double engine_rpm = 0;
  int gear = 0;
  bool has_gearbox = false;
};
inline constexpr double kBrakeLightInput = 0.02;     // applied brake input, [0, 1]
inline constexpr double kBrakeLightTorqueNm = 10.0;  // a wheel's brake torque (full model)
inline constexpr double kReverseLightSpeed = 0.2;    // m/s backwards, with the drive backwards

// Empty when a state can be drawn: four wheels, a usable quaternion, positions within 1e7 m;
// else why not. (Non-finite numbers never get here: the transport drops them.)
std::string CheckState(const pb::VehicleState& s);

// How far each wheel of a vehicle has turned about its axle: the published spin rate integrated
// over simulation time, state by state (trapezoidal rule over the states the viewer took, so a
// recording played back turns the wheels as they turned). The rate is the full model's wheel
// speed omega; the paper model has none, so there it is the rolling speed of B along the wheel's
// heading over the radius (the wheel rolls without slip). A state at the same or an earlier time
// (the same state again, a restart, a take-over) starts again from it without turning.
struct WheelSpin {
  std::array<double, kWheels> angle{};  // rad, in (-pi, pi]
  std::array<double, kWheels> rate{};   // rad/s at the last state
  std::int64_t sim_time_ns = 0;
  bool started = false;
};
void AdvanceWheelSpin(WheelSpin& spin, const pb::VehicleState& s);
// A wheel's spin rate in a state that passed CheckState, rad/s (positive rolling forward).
double WheelSpinRate(const pb::VehicleState& s, int wheel);

// The drawable view of a state that passed CheckState; `spin` turns its wheels.
VehicleView BuildVehicleView(const pb::VehicleState& s, const VehicleGeometry& g,
                             const WheelSpin* spin = nullptr);

}  // namespace vdyn::viewer
