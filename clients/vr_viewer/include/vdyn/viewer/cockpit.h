// The cockpit seen from the driver's seat (the driver camera and the seated headset): a dashboard
// with a speedometer and a tachometer whose needles follow the state, the engaged gear on a
// seven-segment digit between them, the steering wheel turned by the published hand-wheel angle,
// the A-pillars, the roof's front edge and lining with the rear-view mirror's housing, the
// door panels and the floor; three mirrors (the rear-view mirror at the windscreen's top, a side
// mirror on each door) showing the world behind (the renderer draws their images). The bonnet is
// the body's own, drawn from inside with its back faces culled. Laid out from the vehicle's
// geometry (the built-in body's greenhouse and the driver's eyes in it: CabinFor, eyes_B);
// built each frame as triangles in the world frame (draw_list.h).
#pragma once

#include <array>
#include <vector>

#include "vdyn/viewer/math.h"
#include "vdyn/viewer/scene.h"

namespace vdyn::viewer {

class DrawList;
struct MirrorInstance;

// The dials: 0 at the lower left, full scale at the lower right, clockwise through the top.
inline constexpr double kSpeedoFullScaleKmh = 260;
inline constexpr double kDialSweepDeg = 270;
// A dial's needle for a value: rad clockwise from straight up as the driver sees the dial,
// -135 deg at 0, +135 deg at full scale (clamped to the scale).
double DialAngle(double value, double full_scale);
// The tachometer's full scale: the rev limit rounded up to the next 1000 rpm, plus 1000.
double TachoFullScaleRpm(const VehicleGeometry& g);

// Where the cockpit's parts are, body frame (m).
struct CockpitLayout {
  Vec3 wheel_centre_B;
  Vec3 wheel_normal_B;  // the wheel's axis, towards the driver
  Vec3 wheel_up_B;      // in the wheel's plane, its top before it turns
  double wheel_radius = 0.185;
  Vec3 speedo_B, tacho_B;  // dial centres
  Vec3 gauge_normal_B;     // the dials face the eyes
  double gauge_radius = 0.058;
  Vec3 gear_B;  // the gear digit's centre
};
CockpitLayout CockpitFor(const VehicleGeometry& g, const Vec3& seat_B);

// Unlit colours of the dials (exact on the screen; tests find them).
inline constexpr Rgb8 kNeedleColour{255, 80, 0};
inline constexpr Rgb8 kNeedleHubColour{0, 160, 230};
inline constexpr Rgb8 kWheelMarkColour{240, 150, 20};  // the steering wheel's top mark

// A flat mirror, body frame: its glass, a rectangle about centre_B facing the eyes (normal_B),
// right_B the driver's right on it; aimed so the driver's line of sight to its centre reflects
// along look_B (straight back for the rear-view mirror, a little outwards for the side ones).
struct Mirror {
  Vec3 centre_B, normal_B, right_B, up_B;
  double half_width = 0.1, half_height = 0.035;  // m
  Vec3 look_B;
};
enum MirrorIndex { kRearViewMirror = 0, kLeftMirror = 1, kRightMirror = 2, kMirrors = 3 };
std::array<Mirror, kMirrors> MirrorsFor(const VehicleGeometry& g, const Vec3& seat_B);

// Appends the cockpit of a vehicle (its pose, geometry and readings) for eyes at seat_B.
void AppendCockpit(const VehicleView& v, const Vec3& seat_B, DrawList& list);
// Appends its mirrors' glass and what each shows: the view from the mirror's centre along the
// reflected line of sight, and each corner's place in that image - reflected as a real mirror
// reflects (what is behind on the car's left shows on the glass's left as the driver sees it).
void AppendMirrors(const VehicleView& v, const Vec3& seat_B, std::vector<MirrorInstance>& out);
// The projection and view of a mirror's image (near 5 cm, far `far_m`).
Mat4 MirrorViewProj(const MirrorInstance& m, double far_m);

}  // namespace vdyn::viewer
