// The viewer's cameras. Each follows one vehicle (the followed one) and gives a view and a
// projection:
//   chase    behind the vehicle along its heading, looking at it
//   driver   at the driver's eyes (the followed vehicle's, from its geometry: CabinFor's
//            eyes_B), looking along the body's X axis a little down (rolls and pitches with it),
//            in the cockpit (cockpit.h)
//   orbit    around the vehicle at a yaw, pitch and distance fixed in the world (mouse drag, wheel)
//   map      straight down, orthographic, geographic: north up by default
//   north    the paper's geographic camera: behind the vehicle looking north by default, turned in
//            steps by the wheel's paddle shifters (driver input buttons) or the keys Q and E
//   beside   standing on the ground 6 m to the vehicle's left at eye height, facing it
// Map and north share the geographic heading: north_yaw of the world plus the turn.
//
// Horizon lock (chase and orbit): locked (the default), the view keeps the horizon level whatever
// the body does (only the heading turns it); unlocked, it rolls and pitches with the body, as a
// camera bolted to the car would.
//
// In a headset (XrPlace) each camera is a place: its eye point with a level frame facing where
// the camera looks (the head turns and tilts itself), the driver's seat rolling and pitching with
// the body, chase and orbit with the body too when unlocked.
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include "vdyn/viewer/math.h"
#include "vdyn/viewer/scene.h"

namespace vdyn::viewer {

enum class CameraMode { kChase, kDriver, kOrbit, kMap, kNorth, kBeside };
inline constexpr int kCameraModes = 6;
std::string_view CameraName(CameraMode m);
std::optional<CameraMode> CameraFromName(std::string_view name);

struct CameraState {
  CameraMode mode = CameraMode::kChase;
  // The geographic cameras' turn from north, rad, counter-clockwise seen from above (a right
  // paddle turns the view clockwise: the turn decreases).
  double geo_turn = 0;
  double paddle_step = Rad(45);
  double fovy = Rad(60);
  double chase_distance = 8, chase_height = 2.5;
  double north_distance = 14, north_height = 6;
  double orbit_yaw = Rad(-120), orbit_pitch = Rad(25), orbit_distance = 12;  // world frame
  double map_half_height = 30;  // metres from the centre to the top edge
  double beside_distance = 6;   // m to the vehicle's left
  double eye_height = 1.6;      // m above the ground: beside, and a standing headset's eyes
  // The driver camera on the desktop looks this far down from the body's X axis (the road ahead
  // above the cockpit's dials and wheel); a headset's seat stays level with the body.
  double driver_pitch = Rad(-6);
  bool cockpit = true;  // the driver's seat shows the cockpit (key I); else nothing of the car
  bool horizon_locked = true;  // chase and orbit keep the horizon level
};

struct CameraView {
  Mat4 view;  // world to eye
  Mat4 proj;
  Vec3 eye_W;
  // Heading of the view in the ground plane (the direction the top of the screen points on the
  // map), rad from +X_W towards +Y_W: the compass turns with it.
  double heading = 0;
  bool orthographic = false;
  double fovy = 0;              // perspective only
  double metres_per_pixel = 0;  // orthographic only (for arrow thickness)
};

// What a camera looks at when no vehicle is followed: a point and the world's extent.
struct CameraScene {
  const VehicleView* followed = nullptr;
  Vec3 fallback_target_W;
  double north_yaw = kPi / 2;  // the world's north (facility: +Y)
  double far_m = 2000;         // far plane
  double top_z = 100;          // highest terrain point (the map camera stays above it)
};

CameraView ComputeCamera(const CameraState& c, const CameraScene& s, int width_px, int height_px);

// A headset's place for a camera: the world pose of the frame its eyes are in, in OpenXR axes
// (X right, Y up, Z back: it faces along -Z), with its origin at the camera's eye point.
Pose XrPlace(const CameraState& c, const CameraScene& s);

// The body's roll and pitch without its heading (R_WB with its yaw taken out): what an unlocked
// horizon turns the chase and orbit cameras by about the vehicle.
Mat3 Tilt(const Pose& pose_WB, double yaw);

// Where north lies on the screen for a view heading: an angle counter-clockwise from the screen's
// up direction, rad (0: north is straight ahead / up).
double CompassNorthAngle(double north_yaw, double view_heading);

// True when a sphere may be seen through a view-projection (outside all six clip planes: not).
bool InFrustum(const Mat4& view_proj, const Vec3& centre, double radius);

// A paddle press: right turns the geographic cameras clockwise (seen from above) by one step.
void TurnGeographic(CameraState& c, int steps_counter_clockwise);

}  // namespace vdyn::viewer
