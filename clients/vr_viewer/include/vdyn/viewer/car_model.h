// What a vehicle looks like: a car body and its wheels as triangle meshes, built once and drawn
// at each vehicle's pose by the renderer.
//  - The built-in body is a low-poly saloon lofted through cross-sections, placed and sized from
//    the vehicle's geometry: its length, width and the places of its axles are the body box and
//    the mount points the server publishes, its height follows the wheel radius, its wheel
//    arches sit over the wheels at their nominal spring length. It never leaves the body box.
//  - Or a model from a file (glTF/GLB, also OBJ or FBX: Assimp), axes +Y up, +Z forward (the
//    glTF convention), fitted to the same box: scaled to the body's length, its lowest point on
//    the ground. Nodes named like a wheel (wheel, tire, tyre, rim) are left out: the viewer
//    draws its own wheels where the state puts them. The paint (materials named paint, body or
//    carpaint, else the largest) takes the vehicle's colour; materials named like a brake or
//    tail light (brake, tail) light up while braking, like a reversing light (reverse, backup)
//    in reverse.
//  - A wheel: a tyre with a white mark on each sidewall and a five-spoke rim, radius 1, axle
//    along Y; the renderer scales it by the wheel's radius and turns it by its spin.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "vdyn/viewer/math.h"
#include "vdyn/viewer/scene.h"

namespace vdyn::viewer {

// How a surface of a model is shaded.
enum class Material : std::uint8_t {
  kMatte = 0,         // diffuse only
  kPaint = 1,         // the vehicle's colour (times the vertex colour), glossy
  kGlass = 2,         // dark, reflects the sky
  kChrome = 3,        // bright metal, sharp highlights
  kRubber = 4,        // tyres: dark, a soft sheen
  kLightFront = 5,    // headlights: bright whatever the light
  kLightRear = 6,     // tail and brake lights: lit brightly while braking
  kLightReverse = 7,  // reversing lights: lit in reverse
};

struct ModelVertex {
  float p[3];
  float n[3];
  std::uint8_t rgba[4];      // albedo, sRGB
  std::uint8_t material[4];  // [0]: Material
};
static_assert(sizeof(ModelVertex) == 32);

struct ModelMesh {
  std::vector<ModelVertex> vertices;
  std::vector<std::uint32_t> indices;
  Vec3 min, max;  // bounds of the vertices
  // Bounds the fit uses (a file's model: with the wheels that were left out).
  Vec3 fit_min, fit_max;
  std::size_t triangles() const { return indices.size() / 3; }
};

// The numbers the built-in body is made from (body frame, m).
struct CarShape {
  double x_rear = -2.5, x_front = 2.2;  // ends of the body box
  double x_rear_axle = -1.5, x_front_axle = 1.2;
  double half_width = 0.9;
  double z_wheel_centre_front = -0.27, z_wheel_centre_rear = -0.27;  // at the nominal spring
  double radius_front = 0.32, radius_rear = 0.32;
  double z_ground = -0.59;  // under the wheels at the nominal spring length
  double z_roof = 0.85;     // top of the roof
};
// The nominal spring length is 70 % of the free length (about the static load of a car).
CarShape CarShapeFor(const VehicleGeometry& g);

// Where the built-in body's greenhouse is (body frame, m): the stations along X of the rear
// window's base, the roof's rear and front edges and the windscreen's base (the cowl), the belt
// line's height at the cowl and the roof's at its front edge; the driver's eyes (left-hand
// drive). The cockpit is built inside it.
struct Cabin {
  double x_rear_window = 0, x_roof_rear = 0, x_roof_front = 0, x_cowl = 0;
  double z_belt_cowl = 0, z_roof_front = 0;
  // The driver's eyes from T: 15.5 % of the roof's length behind its front edge, 41 % of the
  // half width to the left, a saloon's 1.14 m above the ground scaled (0.21 m over the belt line
  // at the cowl, 0.28 m under the roof's front edge); on the default car {-0.35, 0.37, 0.55}.
  Vec3 eyes_B;
  double half_width = 0.9;
  double z_ground = -0.59;
  double scale = 1;  // heights: a saloon's on 0.32 m wheels, scaled with the wheel radius
  bool axles_inside = true;
  double H(double h) const { return z_ground + h * scale; }  // a saloon's height h, scaled
};
Cabin CabinFor(const VehicleGeometry& g);

// The built-in body for a vehicle's geometry, in its body frame (`coarse`: fewer facets, for a
// vehicle far from the eye).
ModelMesh BuildCarBody(const VehicleGeometry& g, bool coarse = false);

// A wheel of radius 1 centred at the origin, axle along Y, `segments` facets around (at least 12;
// under 16 a coarse wheel: a simpler tyre and flat spokes). Its marks (white strips on both
// sidewalls, from 0.72 to 0.9 of the radius) point along +Z before it turns.
inline constexpr double kTyreWidthPerRadius = 0.65;
ModelMesh BuildWheel(int segments);

class CarModelError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
// A model from a file, in body axes (X forward, Y left, Z up), not yet fitted; throws
// CarModelError naming the file and the reason (unreadable, no triangle, non-finite numbers,
// more than 2 million triangles).
ModelMesh LoadCarModel(const std::string& path);

// The transform from a model's frame to a vehicle's body frame: the built-in body is made in it
// (identity); a file's model is scaled to the body's length, centred across, its lowest point on
// the ground of CarShapeFor.
Mat4 FitModel(const ModelMesh& model, const VehicleGeometry& g, bool built_in);

}  // namespace vdyn::viewer
