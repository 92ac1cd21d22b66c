// The light of the viewer's scene, in linear light: a sun 48 degrees up in the south-west (world
// frame: X east, Y north), the sky's light from above, the ground's bounce from below, and the
// sky's colour at the zenith and at the horizon (which the fog takes far away).
//
// It is balanced so that a face turned straight up in the sun receives exactly 1: such a face
// shows its own colour (a vehicle's roof its palette colour, a road from above its asphalt's
// mean), and a face in shadow keeps the sky's share, about 30 %.
#pragma once

#include "vdyn/viewer/math.h"

namespace vdyn::viewer {

struct Lighting {
  Vec3 sun_W;        // unit, towards the sun
  Vec3 sun_rgb;      // irradiance on a face turned to the sun
  Vec3 sky_rgb;      // hemisphere light on a face turned up
  Vec3 ground_rgb;   // on a face turned down
  Vec3 zenith_rgb;   // the sky straight up
  Vec3 horizon_rgb;  // the sky at the horizon; the fog's colour
};
const Lighting& SceneLighting();

}  // namespace vdyn::viewer
