// What a frame draws of what moves. Triangles built on the CPU each frame for the force arrows and
// the landmarks: one vertex is a position (float, world frame), a normal (zero: drawn unlit, in
// its exact colour - the arrows) and an RGBA colour; the renderer uploads a list in one buffer.
// The vehicles' bodies and wheels are instances of meshes the renderer keeps (car_model.h): a
// pose, a size, a colour.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "vdyn/viewer/math.h"
#include "vdyn/viewer/scene.h"

namespace vdyn::viewer {

struct Vertex {
  float p[3];
  float n[3];
  std::uint8_t rgba[4];
};
static_assert(sizeof(Vertex) == 28);

class DrawList {
 public:
  void Clear() { vertices_.clear(); }
  const std::vector<Vertex>& vertices() const { return vertices_; }
  std::size_t triangles() const { return vertices_.size() / 3; }

  // A box [min, max] in the frame `pose` (lit).
  void Box(const Pose& pose, const Vec3& min, const Vec3& max, Rgb8 c, std::uint8_t alpha = 255);
  // A closed cylinder from a to b.
  void Cylinder(const Vec3& a, const Vec3& b, double radius, Rgb8 c, bool lit, int segments = 12);
  // A cone from its base centre to its tip.
  void Cone(const Vec3& base, const Vec3& tip, double radius, Rgb8 c, bool lit, int segments = 12);
  // An arrow from `from` to `to`: a shaft and a head (unlit). The head takes at most 35 % of the
  // length; a shorter arrow than 2 radii is drawn as its head only.
  void Arrow(const Vec3& from, const Vec3& to, double radius, Rgb8 c, int segments = 12);
  void Triangle(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& n, Rgb8 col,
                std::uint8_t alpha = 255);

 private:
  void Push(const Vec3& p, const Vec3& n, Rgb8 c, std::uint8_t alpha);
  std::vector<Vertex> vertices_;
};

// How the arrows are drawn: length per newton, thickness, which kinds.
struct ArrowStyle {
  double metres_per_newton = 0.5e-3;  // 0.5 m per kN
  double min_length_m = 0.05;         // shorter arrows are not drawn
  bool show[kForceKinds] = {true, true, true, true, true, true};
};

// A car body to draw: the built-in body made for `geometry` (or the model given on the command
// line, fitted to it) at a pose, in the vehicle's colour.
struct BodyInstance {
  std::uint32_t vehicle_id = 0;
  Pose pose_WB;
  VehicleGeometry geometry;
  Rgb8 paint;
  bool coarse = false;
  bool brake_lights = false;    // lit (VehicleView::braking)
  bool reverse_lights = false;  // lit (VehicleView::reversing)
  // Seen from its own driver's seat: drawn with its back faces culled (its bonnet shows through
  // the windscreen; the cockpit stands for the rest).
  bool from_inside = false;
};

// A wheel to draw: the wheel mesh (radius 1, axle along Y) turned into the frame R_WW (columns:
// the wheel's forward turned by its spin, its axle, its up turned by its spin), scaled by its
// radius, at its centre.
struct WheelInstance {
  Vec3 centre_W;
  Mat3 R_WW;
  double radius = 0.3;
  bool coarse = false;
};

// The darkening under a vehicle standing on the ground (the sky's light it keeps off): a
// rectangle around its body on the plane of its contact points, darkest in the middle.
struct ContactShadow {
  std::array<Vec3, 4> corners_W;  // counter-clockwise seen from above
};

// A mirror in the cockpit (cockpit.h): its glass in the world and the view it shows - from
// eye_W along look_W (up_W up), the tangents of its half angles - and where each glass corner
// (the driver's lower left, lower right, upper right, upper left) is in that image (0..1).
struct MirrorInstance {
  int index = 0;  // MirrorIndex: which of the renderer's images
  std::array<Vec3, 4> glass_W;
  std::array<std::array<float, 2>, 4> uv{};
  Vec3 eye_W, look_W, up_W;
  double tan_half_x = 0.2, tan_half_y = 0.1;
};

// The lists of one frame: what is opaque, what is translucent (drawn after), and the force
// arrows (drawn last, in full colour where seen and as a faint ghost where something hides them);
// the cockpit (opaque; no ghost of an arrow is drawn over it); the bodies and wheels of the
// vehicles and their contact shadows; the cockpit's mirrors.
struct FrameLists {
  DrawList opaque, translucent, arrows, cockpit;
  std::vector<BodyInstance> bodies;
  std::vector<WheelInstance> wheels;
  std::vector<ContactShadow> contact_shadows;
  std::vector<MirrorInstance> mirrors;
  void Clear() {
    opaque.Clear();
    cockpit.Clear();
    translucent.Clear();
    arrows.Clear();
    bodies.clear();
    wheels.clear();
    contact_shadows.clear();
    mirrors.clear();
  }
};

// Which parts of a vehicle are drawn (the driver camera leaves out its own car's body, wheels and
// arrows: they would fill the view of the road).
struct VehicleParts {
  bool body = true;    // the body and its contact shadow
  bool wheels = true;  // the wheels, turned by their spin and steering
  bool arrows = true;  // the force arrows
};

// Appends a vehicle's parts: the body at its pose, the wheels at their spring positions and
// steering angles, turned by their spin, and the force arrows. `radius_at(p)` gives an arrow's
// shaft radius at a point (thicker far away, so an arrow stays a few pixels wide). `coarse`:
// fewer facets, for a vehicle far from the eye.
template <class RadiusAt>
void AppendVehicle(const VehicleView& v, const ArrowStyle& style, RadiusAt radius_at,
                   VehicleParts parts, bool coarse, FrameLists& lists);
// The same with `body` false leaving out the body only.
template <class RadiusAt>
void AppendVehicle(const VehicleView& v, const ArrowStyle& style, RadiusAt radius_at, bool body,
                   bool coarse, FrameLists& lists) {
  VehicleParts parts;
  parts.body = body;
  AppendVehicle(v, style, radius_at, parts, coarse, lists);
}

// The radius of a sphere about T that holds the vehicle and its arrows (for culling).
double BoundingRadius(const VehicleView& v, const ArrowStyle& style);

// Where an arrow starts and ends for a style (shared by the renderer and tests).
struct ArrowSpan {
  Vec3 from, to;
};
ArrowSpan ArrowSpanOf(const ForceArrow& a, const ArrowStyle& style);

// --- implementation of the template ---------------------------------------------------------

void AppendVehicleBody(const VehicleView& v, VehicleParts parts, bool coarse, FrameLists& lists);

template <class RadiusAt>
void AppendVehicle(const VehicleView& v, const ArrowStyle& style, RadiusAt radius_at,
                   VehicleParts parts, bool coarse, FrameLists& lists) {
  AppendVehicleBody(v, parts, coarse, lists);
  if (!parts.arrows) return;
  for (const ForceArrow& a : v.arrows) {
    if (!style.show[static_cast<int>(a.kind)]) continue;
    if (Norm(a.force_W) * style.metres_per_newton < style.min_length_m) continue;
    const ArrowSpan s = ArrowSpanOf(a, style);
    lists.arrows.Arrow(s.from, s.to, radius_at(0.5 * (s.from + s.to)), ForceColour(a.kind),
                       coarse ? 6 : 12);
  }
}

}  // namespace vdyn::viewer
