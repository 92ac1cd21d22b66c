#include "vdyn/viewer/car_model.h"

#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <assimp/Importer.hpp>
#include <cctype>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <utility>

#include "vdyn/viewer/mesh_util.h"
#include "vdyn/viewer/textures.h"

namespace vdyn::viewer {
namespace {

// Triangles with a look (material and colour) each, welded and smoothed at the end.
struct Soup {
  std::vector<Vec3> positions;
  std::vector<std::uint32_t> indices;
  std::vector<std::uint32_t> group;  // per triangle: its look
  std::vector<std::pair<Material, Rgb8>> looks;

  std::uint32_t Look(Material m, Rgb8 c) {
    for (std::size_t i = 0; i < looks.size(); ++i) {
      const auto& [lm, lc] = looks[i];
      if (lm == m && lc.r == c.r && lc.g == c.g && lc.b == c.b) {
        return static_cast<std::uint32_t>(i);
      }
    }
    looks.emplace_back(m, c);
    return static_cast<std::uint32_t>(looks.size() - 1);
  }
  void Tri(const Vec3& a, const Vec3& b, const Vec3& c, std::uint32_t look) {
    const auto i = static_cast<std::uint32_t>(positions.size());
    positions.insert(positions.end(), {a, b, c});
    indices.insert(indices.end(), {i, i + 1, i + 2});
    group.push_back(look);
  }
  // Counter-clockwise seen from outside: a, b, c, d.
  void Quad(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d, std::uint32_t look) {
    Tri(a, b, c, look);
    Tri(a, c, d, look);
  }
};

ModelMesh Finish(const Soup& s, double crease_deg) {
  const SmoothedMesh m = SmoothNormals(s.positions, s.indices, s.group, crease_deg);
  ModelMesh out;
  out.vertices.reserve(m.positions.size());
  constexpr double kBig = std::numeric_limits<double>::max();
  out.min = {kBig, kBig, kBig};
  out.max = {-kBig, -kBig, -kBig};
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    ModelVertex v{};
    const Vec3& p = m.positions[i];
    const Vec3& n = m.normals[i];
    v.p[0] = static_cast<float>(p.x);
    v.p[1] = static_cast<float>(p.y);
    v.p[2] = static_cast<float>(p.z);
    v.n[0] = static_cast<float>(n.x);
    v.n[1] = static_cast<float>(n.y);
    v.n[2] = static_cast<float>(n.z);
    const auto& [material, colour] = s.looks[m.group[i]];
    v.rgba[0] = colour.r;
    v.rgba[1] = colour.g;
    v.rgba[2] = colour.b;
    v.rgba[3] = 255;
    v.material[0] = static_cast<std::uint8_t>(material);
    out.vertices.push_back(v);
    out.min = {std::min(out.min.x, p.x), std::min(out.min.y, p.y), std::min(out.min.z, p.z)};
    out.max = {std::max(out.max.x, p.x), std::max(out.max.y, p.y), std::max(out.max.z, p.z)};
  }
  out.indices = m.indices;
  if (out.vertices.empty()) out.min = out.max = Vec3{};
  out.fit_min = out.min;
  out.fit_max = out.max;
  return out;
}

// A piecewise linear function through (x, y) points sorted by x, constant beyond the ends.
double Pwl(const std::vector<std::pair<double, double>>& pts, double x) {
  if (x <= pts.front().first) return pts.front().second;
  for (std::size_t i = 1; i < pts.size(); ++i) {
    if (x <= pts[i].first) {
      const auto& [x0, y0] = pts[i - 1];
      const auto& [x1, y1] = pts[i];
      return x1 - x0 < 1e-9 ? y1 : y0 + (y1 - y0) * (x - x0) / (x1 - x0);
    }
  }
  return pts.back().second;
}

double Mix(double a, double b, double t) {
  return a + (b - a) * t;
}

constexpr Rgb8 kWhite{255, 255, 255};  // paint: the vehicle's colour times this
constexpr Rgb8 kTrim{34, 35, 38};
constexpr Rgb8 kUnderbody{28, 28, 30};
constexpr Rgb8 kGlassTint{22, 28, 34};
constexpr Rgb8 kGrille{18, 18, 20};
constexpr Rgb8 kHeadlight{240, 240, 232};
constexpr Rgb8 kTaillight{170, 18, 22};
constexpr Rgb8 kReverseLight{215, 215, 208};
constexpr Rgb8 kPlate{230, 230, 222};

// A body cross-section at one station: 14 points around, starting at the bottom centre, up the
// left (+Y) side, over the roof and down the right side.
//
//        P6 ___ P7 ___ P6'         P4-P5: the side window (the greenhouse), P6-P7 the roof or
//       P5 /           \ P5'       the windscreen / rear window; where there is no greenhouse
//      P4 |             | P4'      (bonnet, boot) P4..P7 lie on the deck.
//   P3  _/               \_  P3'
//   P2 |                   | P2'   P2: the widest point
//   P1 |________P0_________| P1'
constexpr int kSection = 14;
using Section = std::array<Vec3, kSection>;

}  // namespace

CarShape CarShapeFor(const VehicleGeometry& g) {
  CarShape s;
  s.x_rear = -g.rear;
  s.x_front = g.front;
  s.half_width = g.half_width;
  s.x_front_axle = 0.5 * (g.mount_B[0].x + g.mount_B[1].x);
  s.x_rear_axle = 0.5 * (g.mount_B[2].x + g.mount_B[3].x);
  s.radius_front = 0.5 * (g.radius[0] + g.radius[1]);
  s.radius_rear = 0.5 * (g.radius[2] + g.radius[3]);
  const double spring_front = 0.7 * 0.5 * (g.free_length[0] + g.free_length[1]);
  const double spring_rear = 0.7 * 0.5 * (g.free_length[2] + g.free_length[3]);
  s.z_wheel_centre_front = 0.5 * (g.mount_B[0].z + g.mount_B[1].z) - spring_front;
  s.z_wheel_centre_rear = 0.5 * (g.mount_B[2].z + g.mount_B[3].z) - spring_rear;
  s.z_ground =
      0.5 * (s.z_wheel_centre_front - s.radius_front + s.z_wheel_centre_rear - s.radius_rear);
  const double r = 0.5 * (s.radius_front + s.radius_rear);
  const double scale = std::clamp(r / 0.32, 0.7, 1.6);
  s.z_roof = s.z_ground + 1.46 * scale;
  return s;
}

Cabin CabinFor(const VehicleGeometry& g) {
  const CarShape s = CarShapeFor(g);
  Cabin c;
  const double L = std::max(s.x_front - s.x_rear, 0.5);
  const double xr = s.x_rear, xf = s.x_rear + L;
  const double r = 0.5 * (s.radius_front + s.radius_rear);
  // Heights are those of a saloon on 0.32 m wheels, scaled with the wheel radius.
  c.scale = std::clamp(r / 0.32, 0.7, 1.6);
  c.z_ground = s.z_ground;
  c.half_width = std::max(s.half_width, 0.2);
  // The axles as the cabin's reference; implausible ones (outside the body, or a wheelbase under
  // a third of it) give way to a saloon's proportions.
  double xra = s.x_rear_axle, xfa = s.x_front_axle;
  c.axles_inside = xra > xr && xfa < xf && xfa - xra > L / 3;
  if (!c.axles_inside) {
    xra = xr + 0.21 * L;
    xfa = xf - 0.19 * L;
  }
  const double wb = xfa - xra;
  // The greenhouse: rear window base, roof from rear to front, windscreen base (the cowl).
  std::array<double, 4> cabin = {xra - 0.20 * wb, xra + 0.02 * wb, xra + 0.50 * wb,
                                 xra + 0.78 * wb};
  const double lo = xr + 0.10 * L, hi = xf - 0.22 * L, gap = 0.05 * L;
  for (std::size_t i = 0; i < cabin.size(); ++i) {
    cabin[i] = std::clamp(cabin[i], lo + gap * static_cast<double>(i),
                          hi - gap * static_cast<double>(cabin.size() - 1 - i));
    if (i > 0) cabin[i] = std::max(cabin[i], cabin[i - 1] + gap);
  }
  c.x_rear_window = cabin[0];
  c.x_roof_rear = cabin[1];
  c.x_roof_front = cabin[2];
  c.x_cowl = cabin[3];
  c.z_belt_cowl = c.H(0.93);
  c.z_roof_front = c.H(1.42);
  c.eyes_B = {c.x_roof_front - 0.155 * (c.x_roof_front - c.x_roof_rear), 0.41 * c.half_width,
              c.H(1.14)};
  return c;
}

namespace {

// The built-in body as data. Every length along the body is a key place (below) moved by a
// fraction of the body's length L (the numbers were drawn on a 4.7 m saloon); every height is a
// saloon's in metres, scaled with the wheel radius (Cabin::H); every width a fraction of the half
// width.
//
//   kRear  kRearEnd  kRearWindow  kRoofRear  kBPillar*  kRoofFront  kCowl  kFrontEnd  kFront
//     |__/‾‾‾‾‾‾‾‾‾‾‾‾‾/‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾|‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾\_____________\__|
enum class At : std::uint8_t {
  kRear,
  kRearEnd,  // the rounded ends: min(0.1 m, 0.03 L) in from each end
  kRearWindow,
  kRoofRear,
  kRoofMid,
  kBPillarRear,  // the B pillar, 7 cm wide, 45 % of the way from the roof's rear to its front
  kBPillarFront,
  kRoofFront,
  kCowl,
  kFrontEnd,
  kFront,
  kCount
};
constexpr double kSaloonLength = 4.7;  // m: the body the fractions below were drawn on

struct ProfilePoint {
  At at;
  double dx_saloon;  // m along a 4.7 m saloon, scaled with the body's length
  double value;      // a height (Cabin::H) or a fraction of the half width
};
// The belt line (the side's top edge below the windows), the greenhouse's top (roof, windscreen
// and rear window), the sill and the plan-view width, each sorted by x.
constexpr ProfilePoint kBelt[] = {{At::kRear, 0, 0.74},     {At::kRearEnd, 0, 0.90},
                                  {At::kRear, 0.12, 0.96},  {At::kRearWindow, 0, 0.99},
                                  {At::kCowl, 0, 0.93},     {At::kFront, -0.14, 0.80},
                                  {At::kFrontEnd, 0, 0.74}, {At::kFront, 0, 0.66}};
constexpr ProfilePoint kRoof[] = {{At::kRearWindow, 0, 0.99},
                                  {At::kRoofRear, 0, 1.40},
                                  {At::kRoofMid, 0, 1.44},
                                  {At::kRoofFront, 0, 1.42},
                                  {At::kCowl, 0, 0.93}};
constexpr ProfilePoint kBottom[] = {{At::kRear, 0, 0.34},
                                    {At::kRear, 0.18, 0.22},
                                    {At::kFront, -0.18, 0.20},
                                    {At::kFront, 0, 0.30}};
constexpr ProfilePoint kWidth[] = {{At::kRear, 0, 0.86},     {At::kRearEnd, 0, 0.95},
                                   {At::kRear, 0.4, 1.0},    {At::kFront, -0.45, 1.0},
                                   {At::kFrontEnd, 0, 0.95}, {At::kFront, 0, 0.85}};
// The stations the sections stand at besides the smoothing ones and the wheel arches: every
// place where a profile or a band's look changes.
constexpr ProfilePoint kKeyStations[] = {
    {At::kRear, 0, 0},         {At::kRearEnd, 0, 0},   {At::kRear, 0.12, 0},
    {At::kRearWindow, 0, 0},   {At::kRoofRear, 0, 0},  {At::kBPillarRear, 0, 0},
    {At::kBPillarFront, 0, 0}, {At::kRoofFront, 0, 0}, {At::kCowl, 0, 0},
    {At::kFront, -0.14, 0},    {At::kFrontEnd, 0, 0},  {At::kFront, 0, 0}};

// The body's looks, registered in this order.
enum Look : std::uint32_t {
  kPaintLook,
  kGlassLook,
  kTrimLook,
  kUnderLook,
  kHeadLook,
  kTailLook,
  kReverseLook,
  kGrilleLook,
  kPlateLook,
  kLookCount
};
constexpr std::pair<Material, Rgb8> kLooks[kLookCount] = {{Material::kPaint, kWhite},
                                                          {Material::kGlass, kGlassTint},
                                                          {Material::kMatte, kTrim},
                                                          {Material::kMatte, kUnderbody},
                                                          {Material::kLightFront, kHeadlight},
                                                          {Material::kLightRear, kTaillight},
                                                          {Material::kLightReverse, kReverseLight},
                                                          {Material::kMatte, kGrille},
                                                          {Material::kMatte, kPlate}};

// Details on the ends, a few millimetres proud: headlights, grille and the lower intake at the
// front; tail lights, reversing lamps (inboard of the tail lights, in their band) and the number
// plate at the back. y as fractions of the end's half width (a pair: one each side, mirrored),
// heights as Cabin::H.
struct EndPanel {
  Look look;
  bool front, pair;
  double y0, y1, h0, h1;
};
constexpr EndPanel kEndPanels[] = {{kHeadLook, true, true, 0.52, 0.84, 0.53, 0.62},
                                   {kTailLook, false, true, 0.58, 0.88, 0.60, 0.70},
                                   {kReverseLook, false, true, 0.47, 0.56, 0.61, 0.69},
                                   {kGrilleLook, true, false, -0.40, 0.40, 0.38, 0.52},
                                   {kGrilleLook, true, false, -0.70, 0.70, 0.24, 0.33},
                                   {kPlateLook, false, false, -0.26, 0.26, 0.45, 0.56}};

// The key places of one body, and its profiles in metres.
struct BodyPlan {
  std::array<double, static_cast<std::size_t>(At::kCount)> x{};
  double length = 0, half_width = 0, scale = 1;
  Cabin cab;
  double x_b = 0;  // the B pillar's centre
  std::vector<std::pair<double, double>> belt, roof, bottom, width;

  double X(const ProfilePoint& p) const {
    return x[static_cast<std::size_t>(p.at)] + p.dx_saloon * length / kSaloonLength;
  }
  double Rear() const { return x[static_cast<std::size_t>(At::kRear)]; }
  double Front() const { return x[static_cast<std::size_t>(At::kFront)]; }
  double XAt(At a) const { return x[static_cast<std::size_t>(a)]; }
};

template <std::size_t N>
std::vector<std::pair<double, double>> Heights(const BodyPlan& b, const ProfilePoint (&t)[N]) {
  std::vector<std::pair<double, double>> out;
  for (const ProfilePoint& p : t) out.emplace_back(b.X(p), b.cab.H(p.value));
  return out;
}

BodyPlan PlanBody(const VehicleGeometry& g) {
  const CarShape s = CarShapeFor(g);
  BodyPlan b;
  b.cab = CabinFor(g);
  b.length = std::max(s.x_front - s.x_rear, 0.5);
  b.half_width = b.cab.half_width;
  b.scale = b.cab.scale;
  const double xr = s.x_rear, xf = s.x_rear + b.length;
  const double end = std::min(0.1, 0.03 * b.length);
  b.x_b = Mix(b.cab.x_roof_rear, b.cab.x_roof_front, 0.45);
  b.x = {xr,
         xr + end,
         b.cab.x_rear_window,
         b.cab.x_roof_rear,
         Mix(b.cab.x_roof_rear, b.cab.x_roof_front, 0.5),
         b.x_b - 0.035,
         b.x_b + 0.035,
         b.cab.x_roof_front,
         b.cab.x_cowl,
         xf - end,
         xf};
  b.belt = Heights(b, kBelt);
  b.roof = Heights(b, kRoof);
  b.bottom = Heights(b, kBottom);
  for (const ProfilePoint& p : kWidth) b.width.emplace_back(b.X(p), p.value);
  return b;
}

// Stations along X: the key places, and the wheel arches (a half circle over each axle at the
// nominal wheel centre, 7 cm above the tyre; the body's bottom follows it), sorted by x.
struct Station {
  double x, z_bottom;
};
std::vector<Station> BodyStations(const VehicleGeometry& g, const BodyPlan& b, bool coarse) {
  const CarShape s = CarShapeFor(g);
  const double xr = b.Rear(), xf = b.Front();
  std::vector<Station> stations;
  auto add = [&](double x) { stations.push_back({x, Pwl(b.bottom, x)}); };
  for (const ProfilePoint& p : kKeyStations) add(b.X(p));
  if (!coarse) {
    for (double x = xr + 0.3; x < xf - 0.3; x += 0.3) add(x);  // smooth sides between the keys
  }
  struct Arch {
    double x, z_centre, radius;
  };
  std::vector<Arch> arches;
  if (b.cab.axles_inside) {
    arches.push_back({s.x_rear_axle, s.z_wheel_centre_rear, s.radius_rear + 0.07});
    arches.push_back({s.x_front_axle, s.z_wheel_centre_front, s.radius_front + 0.07});
  }
  std::erase_if(stations, [&](const Station& st) {
    for (const Arch& a : arches) {
      if (std::abs(st.x - a.x) <= a.radius + 0.02) return true;
    }
    return false;
  });
  for (const Arch& a : arches) {
    if (a.x - a.radius < xr + 0.05 || a.x + a.radius > xf - 0.05) continue;
    const double base_in = Pwl(b.bottom, a.x - a.radius), base_out = Pwl(b.bottom, a.x + a.radius);
    stations.push_back({a.x - a.radius, base_in});
    const int arch_steps = coarse ? 5 : 10;
    for (int k = 0; k <= arch_steps; ++k) {
      const double t = kPi * (1.0 - static_cast<double>(k) / arch_steps);
      stations.push_back(
          {a.x + a.radius * std::cos(t), std::max(a.z_centre + a.radius * std::sin(t), base_in)});
    }
    stations.push_back({a.x + a.radius, base_out});
  }
  std::stable_sort(stations.begin(), stations.end(),
                   [](const Station& p, const Station& q) { return p.x < q.x - 1e-9; });
  // Keep the first of stations closer than 1 mm unless they are an arch's vertical edge.
  std::vector<Station> unique;
  for (const Station& st : stations) {
    if (!unique.empty() && std::abs(st.x - unique.back().x) < 1e-3 &&
        std::abs(st.z_bottom - unique.back().z_bottom) < 1e-3) {
      continue;
    }
    unique.push_back(st);
  }
  return unique;
}

// The body's cross-section at a station (the 14 points of Section).
Section SectionAt(const BodyPlan& b, const Station& st) {
  const double x = st.x;
  const double w = b.half_width * Pwl(b.width, x);
  const double zb = st.z_bottom;
  const double zmid = std::max(b.cab.H(0.55), zb + 0.03);
  const double zbelt = std::max(Pwl(b.belt, x), zmid + 0.05);
  const bool greenhouse = x > b.XAt(At::kRearWindow) && x < b.XAt(At::kCowl);
  const double gh = greenhouse ? std::max(Pwl(b.roof, x) - zbelt, 0.0) : 0.0;
  const double k = std::clamp(gh / 0.15, 0.0, 1.0);
  const double ztop = zbelt + std::max(gh, 0.02);
  const std::array<Vec3, 8> half = {
      Vec3{x, 0, zb},
      Vec3{x, 0.97 * w, zb},
      Vec3{x, w, zmid},
      Vec3{x, 0.975 * w, zbelt},
      Vec3{x, 0.94 * w, zbelt + 0.01},
      Vec3{x, Mix(0.90, 0.74, k) * w, zbelt + std::max(gh - 0.04, 0.015)},
      Vec3{x, Mix(0.86, 0.68, k) * w, ztop},
      Vec3{x, 0, ztop + 0.02 + 0.02 * k},
  };
  Section sec;
  for (std::size_t i = 0; i < 8; ++i) sec[i] = half[i];
  for (std::size_t i = 1; i <= 6; ++i) {  // down the right side
    const Vec3& p = half[7 - i];
    sec[7 + i] = {p.x, -p.y, p.z};
  }
  return sec;
}

// The look of the band between points i and i+1 of the left half (mirrored on the right) over
// stations at xm.
Look BandLook(const BodyPlan& b, int i, double xm) {
  const double L = b.length, xr = b.Rear(), xf = b.Front();
  const bool rear_window = xm > b.XAt(At::kRearWindow) && xm < b.XAt(At::kRoofRear);
  const bool roof_zone = xm > b.XAt(At::kRoofRear) && xm < b.XAt(At::kRoofFront);
  const bool screen = xm > b.XAt(At::kRoofFront) && xm < b.XAt(At::kCowl);
  const bool b_pillar = std::abs(xm - b.x_b) < 0.035;
  switch (i) {
    case 0:
      return kUnderLook;
    case 1:  // the lower side: paint, black bumpers at the ends
      return (xm < xr + 0.25 * L / kSaloonLength || xm > xf - 0.2 * L / kSaloonLength) ? kTrimLook
                                                                                       : kPaintLook;
    case 4:
      if (roof_zone) return b_pillar ? kTrimLook : kGlassLook;
      return screen ? kGlassLook : kPaintLook;
    case 6:
      return (rear_window || screen) ? kGlassLook : kPaintLook;
    default:
      return kPaintLook;
  }
}

// The shell: bands between consecutive sections, and the end caps (fans from the section's
// middle) facing back and forward.
void AddShell(Soup& soup, const std::array<std::uint32_t, kLookCount>& looks, const BodyPlan& b,
              const std::vector<Station>& stations) {
  std::vector<Section> secs;
  for (const Station& st : stations) secs.push_back(SectionAt(b, st));
  for (std::size_t j = 0; j + 1 < secs.size(); ++j) {
    const Section &p = secs[j], &q = secs[j + 1];
    const double xm = 0.5 * (stations[j].x + stations[j + 1].x);
    for (std::size_t i = 0; i < kSection; ++i) {
      const std::size_t n = (i + 1) % kSection;
      const int band = i < 7 ? static_cast<int>(i) : 13 - static_cast<int>(i);  // mirrored
      soup.Quad(p[i], p[n], q[n], q[i], looks[BandLook(b, band, xm)]);
    }
  }
  for (const bool front : {false, true}) {
    const Section& sec = front ? secs.back() : secs.front();
    Vec3 c;
    for (const Vec3& p : sec) c += p / kSection;
    for (std::size_t i = 0; i < kSection; ++i) {
      const Vec3& p = sec[i];
      const Vec3& q = sec[(i + 1) % kSection];
      if (front) {
        soup.Tri(c, p, q, looks[kPaintLook]);
      } else {
        soup.Tri(c, q, p, looks[kPaintLook]);
      }
    }
  }
}

void AddEndPanels(Soup& soup, const std::array<std::uint32_t, kLookCount>& looks,
                  const BodyPlan& b) {
  const double wf = b.half_width * Pwl(b.width, b.Front());
  const double wr = b.half_width * Pwl(b.width, b.Rear());
  auto panel = [&](const EndPanel& e, double side) {
    const double w = e.front ? wf : wr;
    const double x = e.front ? b.Front() + 0.004 : b.Rear() - 0.004;
    const double y0 = std::min(side * e.y0, side * e.y1) * w;
    const double y1 = std::max(side * e.y0, side * e.y1) * w;
    const double z0 = b.cab.H(e.h0), z1 = b.cab.H(e.h1);
    const Vec3 p{x, y0, z0}, q{x, y1, z0}, r{x, y1, z1}, t{x, y0, z1};
    if (e.front) {
      soup.Quad(p, q, r, t, looks[e.look]);  // facing +X
    } else {
      soup.Quad(p, t, r, q, looks[e.look]);  // facing -X
    }
  };
  for (const double side : {1.0, -1.0}) {
    for (const EndPanel& e : kEndPanels) {
      if (e.pair) panel(e, side);
    }
  }
  for (const EndPanel& e : kEndPanels) {
    if (!e.pair) panel(e, 1.0);
  }
}

// Door mirrors: small wedges on the doors at the windscreen's base, inside the body box.
void AddDoorMirrors(Soup& soup, const std::array<std::uint32_t, kLookCount>& looks,
                    const BodyPlan& b) {
  const double x_cowl = b.XAt(At::kCowl), hw = b.half_width;
  for (const double side : {1.0, -1.0}) {
    const double zb = Pwl(b.belt, x_cowl) + 0.03, zt = zb + 0.11 * b.scale;
    const double x0 = x_cowl - 0.16, x1 = x_cowl - 0.04;
    const double yi = side * 0.9 * hw, yo = side * hw;
    const Vec3 p[8] = {{x0, yi, zb}, {x1, yi, zb}, {x1, yo, zb}, {x0, yo, zb},
                       {x0, yi, zt}, {x1, yi, zt}, {x1, yo, zt}, {x0, yo, zt}};
    auto q = [&](int i, int j, int k, int l, Look look) {
      if (side > 0) {
        soup.Quad(p[i], p[j], p[k], p[l], looks[look]);
      } else {
        soup.Quad(p[i], p[l], p[k], p[j], looks[look]);
      }
    };
    q(0, 3, 2, 1, kPaintLook);  // bottom
    q(4, 5, 6, 7, kPaintLook);  // top
    q(1, 2, 6, 5, kTrimLook);   // forward face
    q(0, 4, 7, 3, kGlassLook);  // the glass, facing back
    q(3, 7, 6, 2, kPaintLook);  // outer side
    q(0, 1, 5, 4, kPaintLook);  // inner side
  }
}

}  // namespace

ModelMesh BuildCarBody(const VehicleGeometry& g, bool coarse) {
  const BodyPlan plan = PlanBody(g);
  Soup soup;
  std::array<std::uint32_t, kLookCount> looks{};
  for (std::size_t i = 0; i < kLookCount; ++i)
    looks[i] = soup.Look(kLooks[i].first, kLooks[i].second);
  AddShell(soup, looks, plan, BodyStations(g, plan, coarse));
  AddEndPanels(soup, looks, plan);
  AddDoorMirrors(soup, looks, plan);
  return Finish(soup, 40.0);
}

ModelMesh BuildWheel(int segments) {
  segments = std::max(segments, 12);
  Soup soup;
  const std::uint32_t tread = soup.Look(Material::kRubber, {26, 26, 28});
  const std::uint32_t wall = soup.Look(Material::kRubber, {38, 38, 41});
  const std::uint32_t mark = soup.Look(Material::kMatte, {236, 236, 230});
  const std::uint32_t rim = soup.Look(Material::kChrome, {182, 185, 190});
  const std::uint32_t disc = soup.Look(Material::kMatte, {58, 56, 54});
  const std::uint32_t cap = soup.Look(Material::kMatte, {30, 30, 34});
  const double hw = 0.5 * kTyreWidthPerRadius;
  // The tyre's cross-section (radius, axial offset), from the bead on the left (+Y) over the
  // tread to the bead on the right.
  const bool detailed = segments >= 16;
  const std::vector<std::pair<double, double>> profile =
      detailed ? std::vector<std::pair<double, double>>{{0.60, 0.84 * hw},   {0.70, 0.97 * hw},
                                                        {0.86, 1.0 * hw},    {0.955, 0.92 * hw},
                                                        {0.995, 0.77 * hw},  {1.0, 0.0},
                                                        {0.995, -0.77 * hw}, {0.955, -0.92 * hw},
                                                        {0.86, -1.0 * hw},   {0.70, -0.97 * hw},
                                                        {0.60, -0.84 * hw}}
               : std::vector<std::pair<double, double>>{{0.60, 0.84 * hw}, {0.86, 1.0 * hw},
                                                        {0.99, 0.8 * hw},  {0.99, -0.8 * hw},
                                                        {0.86, -1.0 * hw}, {0.60, -0.84 * hw}};
  // A point at radius rho and axial offset y, at angle t from +Z towards +X.
  auto at = [](double rho, double y, double t) {
    return Vec3{rho * std::sin(t), y, rho * std::cos(t)};
  };
  for (int i = 0; i < segments; ++i) {
    const double t0 = 2 * kPi * i / segments, t1 = 2 * kPi * (i + 1) / segments;
    for (std::size_t k = 0; k + 1 < profile.size(); ++k) {
      const auto [r0, y0] = profile[k];
      const auto [r1, y1] = profile[k + 1];
      const bool on_tread = r0 > 0.99 || r1 > 0.99 || (r0 > 0.95 && r1 > 0.95);
      // Outward: (along the profile) x (along the turn) points away from the axle.
      soup.Quad(at(r0, y0, t0), at(r1, y1, t0), at(r1, y1, t1), at(r0, y0, t1),
                on_tread ? tread : wall);
    }
  }
  // The marks: a strip on each sidewall, 8 % of the radius wide, along +Z.
  for (double side : {1.0, -1.0}) {
    const double y = side * (1.0 * hw + 0.006);
    const Vec3 a{-0.04, y, 0.72}, b{0.04, y, 0.72}, c{0.04, y, 0.90}, d{-0.04, y, 0.90};
    if (side > 0) {
      soup.Quad(a, d, c, b, mark);
    } else {
      soup.Quad(a, b, c, d, mark);
    }
  }
  // The rim on both faces: a lip, five spokes from the hub, the brake disc behind them.
  const int spoke_steps = detailed ? std::max(segments, 20) : segments;
  for (double side : {1.0, -1.0}) {
    auto face = [&](const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d, std::uint32_t l) {
      // Quads given with their normal along +Y; flipped for the right face.
      if (side > 0) {
        soup.Quad(a, b, c, d, l);
      } else {
        soup.Quad(a, d, c, b, l);
      }
    };
    auto p = [&](double rho, double y, double t) { return at(rho, side * y, t); };
    for (int i = 0; i < segments; ++i) {
      const double t0 = 2 * kPi * i / segments, t1 = 2 * kPi * (i + 1) / segments;
      face(p(0.56, 0.80 * hw, t1), p(0.56, 0.80 * hw, t0), p(0.61, 0.84 * hw, t0),
           p(0.61, 0.84 * hw, t1), rim);
      face(p(0.0, 0.15 * hw, t1), p(0.0, 0.15 * hw, t0), p(0.56, 0.15 * hw, t0),
           p(0.56, 0.15 * hw, t1), disc);
    }
    for (int i = 0; i < spoke_steps; ++i) {
      const double t0 = 2 * kPi * i / spoke_steps, t1 = 2 * kPi * (i + 1) / spoke_steps;
      // Hub: a low dome, the centre cap dark.
      face(p(0.06, 0.80 * hw, t1), p(0.06, 0.80 * hw, t0), p(0.17, 0.74 * hw, t0),
           p(0.17, 0.74 * hw, t1), rim);
      soup.Tri(p(0.0, 0.82 * hw, 0), side > 0 ? p(0.06, 0.80 * hw, t0) : p(0.06, 0.80 * hw, t1),
               side > 0 ? p(0.06, 0.80 * hw, t1) : p(0.06, 0.80 * hw, t0), cap);
    }
    for (int s = 0; s < 5; ++s) {
      const double c = 2 * kPi * s / 5 + kPi / 5;  // no spoke on the mark's line
      const double root = Rad(11), tip = Rad(6.5);
      const Vec3 a = p(0.16, 0.74 * hw, c - root), b = p(0.16, 0.74 * hw, c + root);
      const Vec3 e = p(0.565, 0.70 * hw, c + tip), d = p(0.565, 0.70 * hw, c - tip);
      face(b, a, d, e, rim);
      if (!detailed) continue;
      // The spoke's edges, down to the disc.
      const Vec3 a2 = p(0.16, 0.3 * hw, c - root), d2 = p(0.565, 0.3 * hw, c - tip);
      const Vec3 b2 = p(0.16, 0.3 * hw, c + root), e2 = p(0.565, 0.3 * hw, c + tip);
      face(a, a2, d2, d, rim);
      face(b, e, e2, b2, rim);
    }
  }
  ModelMesh m = Finish(soup, 35.0);
  return m;
}

namespace {

bool NameHas(std::string name, std::initializer_list<const char*> words) {
  std::transform(name.begin(), name.end(), name.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  for (const char* w : words) {
    if (name.find(w) != std::string::npos) return true;
  }
  return false;
}

Rgb8 ColourOf(const aiMaterial& m, float* opacity) {
  aiColor4D c(0.7f, 0.7f, 0.7f, 1.0f);
  if (m.Get(AI_MATKEY_BASE_COLOR, c) != AI_SUCCESS) {
    aiColor3D d(0.7f, 0.7f, 0.7f);
    if (m.Get(AI_MATKEY_COLOR_DIFFUSE, d) == AI_SUCCESS) c = aiColor4D(d.r, d.g, d.b, 1.0f);
  }
  float o = c.a;
  if (m.Get(AI_MATKEY_OPACITY, o) != AI_SUCCESS) o = c.a;
  *opacity = std::min(o, c.a);
  // glTF's base colour factors are linear: to sRGB.
  return {ToSrgb(c.r), ToSrgb(c.g), ToSrgb(c.b)};
}

}  // namespace

ModelMesh LoadCarModel(const std::string& path) {
  Assimp::Importer importer;
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE,
                              aiPrimitiveType_POINT | aiPrimitiveType_LINE);
  const aiScene* scene =
      importer.ReadFile(path, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices |
                                  aiProcess_SortByPType | aiProcess_FindDegenerates |
                                  aiProcess_FindInvalidData | aiProcess_ValidateDataStructure);
  if (scene == nullptr || scene->mRootNode == nullptr ||
      (scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE) != 0) {
    throw CarModelError("car model '" + path + "': " + importer.GetErrorString());
  }
  // Looks by material: paint by name, glass by name or opacity, else the material's colour.
  std::vector<std::pair<Material, Rgb8>> looks(scene->mNumMaterials);
  std::vector<bool> named_paint(scene->mNumMaterials, false);
  bool any_paint = false;
  for (unsigned i = 0; i < scene->mNumMaterials; ++i) {
    const aiMaterial& m = *scene->mMaterials[i];
    const std::string name = m.GetName().C_Str();
    float opacity = 1;
    const Rgb8 c = ColourOf(m, &opacity);
    if (NameHas(name, {"paint", "body", "carpaint"})) {
      looks[i] = {Material::kPaint, kWhite};
      named_paint[i] = any_paint = true;
    } else if (NameHas(name, {"glass", "window"}) || opacity < 0.9f) {
      looks[i] = {Material::kGlass, kGlassTint};
    } else if (NameHas(name, {"reverse", "backup"})) {
      looks[i] = {Material::kLightReverse, c};
    } else if (NameHas(name, {"brake", "tail"})) {
      looks[i] = {Material::kLightRear, c};
    } else if (NameHas(name, {"chrome", "metal"})) {
      looks[i] = {Material::kChrome, c};
    } else {
      looks[i] = {Material::kMatte, c};
    }
  }
  // The triangles of every node but the wheels, in body axes: X = glTF +Z, Y = +X, Z = +Y.
  constexpr double kBig = std::numeric_limits<double>::max();
  Vec3 all_min{kBig, kBig, kBig}, all_max{-kBig, -kBig, -kBig};
  std::vector<Vec3> positions;
  std::vector<std::uint32_t> indices, group;
  std::vector<double> area(scene->mNumMaterials, 0.0);
  constexpr std::size_t kMaxTriangles = 2'000'000;
  std::function<void(const aiNode*, const aiMatrix4x4&, bool)> walk = [&](const aiNode* node,
                                                                          const aiMatrix4x4& parent,
                                                                          bool wheel) {
    const aiMatrix4x4 t = parent * node->mTransformation;
    wheel = wheel || NameHas(node->mName.C_Str(), {"wheel", "tire", "tyre", "rim"});
    for (unsigned mi = 0; mi < node->mNumMeshes; ++mi) {
      const aiMesh& mesh = *scene->mMeshes[node->mMeshes[mi]];
      if ((mesh.mPrimitiveTypes & aiPrimitiveType_TRIANGLE) == 0) continue;
      const auto base = static_cast<std::uint32_t>(positions.size());
      for (unsigned v = 0; v < mesh.mNumVertices; ++v) {
        const aiVector3D p = t * mesh.mVertices[v];
        const Vec3 b{p.z, p.x, p.y};
        if (!std::isfinite(b.x) || !std::isfinite(b.y) || !std::isfinite(b.z)) {
          throw CarModelError("car model '" + path + "': mesh '" + mesh.mName.C_Str() +
                              "' has a vertex that is not a finite number");
        }
        all_min = {std::min(all_min.x, b.x), std::min(all_min.y, b.y), std::min(all_min.z, b.z)};
        all_max = {std::max(all_max.x, b.x), std::max(all_max.y, b.y), std::max(all_max.z, b.z)};
        if (!wheel) positions.push_back(b);
      }
      if (wheel) continue;
      for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
        const aiFace& face = mesh.mFaces[f];
        if (face.mNumIndices != 3) continue;
        for (unsigned k = 0; k < 3; ++k) indices.push_back(base + face.mIndices[k]);
        group.push_back(mesh.mMaterialIndex);
        const Vec3 &a = positions[base + face.mIndices[0]], &b = positions[base + face.mIndices[1]],
                   &c = positions[base + face.mIndices[2]];
        if (mesh.mMaterialIndex < area.size()) {
          area[mesh.mMaterialIndex] += 0.5 * Norm(Cross(b - a, c - a));
        }
      }
      if (group.size() > kMaxTriangles) {
        throw CarModelError("car model '" + path + "': more than 2 million triangles");
      }
    }
    for (unsigned c = 0; c < node->mNumChildren; ++c) walk(node->mChildren[c], t, wheel);
  };
  walk(scene->mRootNode, aiMatrix4x4(), false);
  if (group.empty()) {
    throw CarModelError("car model '" + path + "': holds no triangle (apart from wheels)");
  }
  if (!any_paint && !area.empty()) {
    const auto largest =
        static_cast<std::size_t>(std::max_element(area.begin(), area.end()) - area.begin());
    looks[largest] = {Material::kPaint, kWhite};
  }
  Soup soup;
  soup.positions = std::move(positions);
  soup.indices = std::move(indices);
  std::map<std::uint32_t, std::uint32_t> look_of_material;
  soup.group.reserve(group.size());
  for (std::uint32_t m : group) {
    if (!look_of_material.count(m)) {
      const auto& [material, colour] =
          m < looks.size() ? looks[m]
                           : std::pair<Material, Rgb8>{Material::kMatte, {180, 180, 180}};
      look_of_material[m] = soup.Look(material, colour);
    }
    soup.group.push_back(look_of_material[m]);
  }
  ModelMesh out = Finish(soup, 45.0);
  out.fit_min = all_min;
  out.fit_max = all_max;
  if (!(out.fit_max.x - out.fit_min.x > 1e-6)) {
    throw CarModelError("car model '" + path + "': has no length along +Z (forward)");
  }
  return out;
}

Mat4 FitModel(const ModelMesh& model, const VehicleGeometry& g, bool built_in) {
  if (built_in) return Mat4{};
  const CarShape s = CarShapeFor(g);
  const double length = model.fit_max.x - model.fit_min.x;
  const double k = (s.x_front - s.x_rear) / std::max(length, 1e-6);
  Mat4 m;
  m(0, 0) = m(1, 1) = m(2, 2) = k;
  m(0, 3) = s.x_rear - k * model.fit_min.x;
  m(1, 3) = -k * 0.5 * (model.fit_min.y + model.fit_max.y);
  m(2, 3) = s.z_ground - k * model.fit_min.z;
  return m;
}

}  // namespace vdyn::viewer
