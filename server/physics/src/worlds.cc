// Built-in worlds, generated in code (no asset files).
#include <cmath>
#include <cstdint>
#include <functional>
#include <numbers>

#include "vdyn/physics/world.h"

namespace vdyn {

const Eigen::Vector3d& World::LandmarkAt(const std::string& landmark) const {
  for (const auto& l : landmarks) {
    if (l.name == landmark) return l.p_W;
  }
  throw std::out_of_range("world '" + name + "' has no landmark '" + landmark + "'");
}

namespace {

using Vec3 = Eigen::Vector3d;

// A surface z = f(x, y) over the grid xs x ys (both increasing).
TriangleMesh HeightfieldMesh(std::string name, SurfaceKind kind, const std::vector<double>& xs,
                             const std::vector<double>& ys,
                             const std::function<double(double, double)>& f) {
  TriangleMesh m;
  m.name = std::move(name);
  m.kind = kind;
  const auto nx = static_cast<std::uint32_t>(xs.size());
  const auto ny = static_cast<std::uint32_t>(ys.size());
  m.vertices_W.reserve(static_cast<std::size_t>(nx) * ny);
  for (std::uint32_t j = 0; j < ny; ++j) {
    for (std::uint32_t i = 0; i < nx; ++i) m.vertices_W.emplace_back(xs[i], ys[j], f(xs[i], ys[j]));
  }
  m.triangles.reserve(2 * static_cast<std::size_t>(nx - 1) * (ny - 1));
  for (std::uint32_t j = 0; j + 1 < ny; ++j) {
    for (std::uint32_t i = 0; i + 1 < nx; ++i) {
      const std::uint32_t a = j * nx + i, b = a + 1, c = a + nx + 1, d = a + nx;
      m.triangles.push_back({a, b, c});
      m.triangles.push_back({a, c, d});
    }
  }
  return m;
}

std::vector<double> Range(double lo, double hi, double step) {
  std::vector<double> v;
  const auto n = static_cast<int>(std::ceil((hi - lo) / step - 1e-9));
  for (int i = 0; i <= n; ++i) v.push_back(std::min(hi, lo + step * i));
  return v;
}

double SmoothStep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

// Deterministic value noise: a hash of the lattice point, smoothly interpolated. Same numbers on
// every machine (integer hashing, no library random generator).
double LatticeValue(std::int64_t i, std::int64_t j, std::uint64_t seed) {
  std::uint64_t h = seed ^ (static_cast<std::uint64_t>(i) * 0x9E3779B97F4A7C15ull) ^
                    (static_cast<std::uint64_t>(j) * 0xC2B2AE3D27D4EB4Full);
  h ^= h >> 33;
  h *= 0xFF51AFD7ED558CCDull;
  h ^= h >> 33;
  h *= 0xC4CEB9FE1A85EC53ull;
  h ^= h >> 33;
  return static_cast<double>(h >> 11) * (2.0 / 9007199254740992.0) - 1.0;  // [-1, 1)
}

double ValueNoise(double x, double y, std::uint64_t seed) {
  const double fx = std::floor(x), fy = std::floor(y);
  const auto i = static_cast<std::int64_t>(fx), j = static_cast<std::int64_t>(fy);
  const double tx = SmoothStep(0, 1, x - fx), ty = SmoothStep(0, 1, y - fy);
  const double a = LatticeValue(i, j, seed), b = LatticeValue(i + 1, j, seed);
  const double c = LatticeValue(i, j + 1, seed), d = LatticeValue(i + 1, j + 1, seed);
  return (a + (b - a) * tx) * (1 - ty) + (c + (d - c) * tx) * ty;
}

// Facility layout (metres, world frame; +X east, +Y north, Z up):
//
//   y=+190 ===================== glass barrier ======================  (inner faces)
//            [billboard at (0, 170)]
//                  +----------- rough terrain ------------+   y in [-10, 90]
//                  |      x in [-60, 60], bumps <= 0.3 m   |
//                  +---------------------------------------+
//   ramp B (open ground, facing east) at x in [120, 126.4], y in [-70, -64]
//   y=-150  ->  test road x in [-262, 262], 8 m wide: speed bumps at -180/-160/-140,
//               washboard -100..-80, one-sided bump at -40, jump ramp A at x in [40, 44.5]
//   y=-190 ===================== glass barrier ======================
//         x=-290                                                 x=+290
constexpr double kBarrierX = 290.0, kBarrierY = 190.0;
constexpr double kBarrierThickness = 0.3, kBarrierHeight = 1.5;
constexpr double kRoadY = -150.0, kRoadHalfWidth = 4.0, kRoadX = 262.0, kRoadZ = 0.02;

double RoadHeight(double x, double y) {
  const double across = 1.0 - SmoothStep(kRoadHalfWidth, kRoadHalfWidth + 0.4, std::abs(y - kRoadY));
  const double along = 1.0 - SmoothStep(kRoadX, kRoadX + 0.4, std::abs(x));
  return kRoadZ * across * along;
}

// Speed bump: half-sine, `length` along X, across the lanes [y0, y1].
TriangleMesh Bump(const std::string& name, double x0, double length, double height, double y0,
                  double y1) {
  return HeightfieldMesh(name, SurfaceKind::kObstacle, Range(x0, x0 + length, 0.05), {y0, y1},
                         [=](double x, double) {
                           return kRoadZ + height * std::sin(std::numbers::pi * (x - x0) / length);
                         });
}

// Wedge ramp rising along +X from x0 to its top edge at height h, with side and back faces.
TriangleMesh Ramp(const std::string& name, double x0, double y0, double y1, double slope_deg,
                  double h, double base_z) {
  TriangleMesh m;
  m.name = name;
  m.kind = SurfaceKind::kRamp;
  const double len = h / std::tan(slope_deg * std::numbers::pi / 180.0);
  const double x1 = x0 + len, zt = base_z + h;
  m.AddQuad(Vec3(x0, y0, base_z), Vec3(x1, y0, zt), Vec3(x1, y1, zt), Vec3(x0, y1, base_z));
  m.AddQuad(Vec3(x1, y0, base_z), Vec3(x1, y1, base_z), Vec3(x1, y1, zt), Vec3(x1, y0, zt));
  // side triangles
  const auto i = static_cast<std::uint32_t>(m.vertices_W.size());
  m.vertices_W.insert(m.vertices_W.end(), {Vec3(x0, y0, base_z), Vec3(x1, y0, base_z),
                                           Vec3(x1, y0, zt), Vec3(x0, y1, base_z),
                                           Vec3(x1, y1, zt), Vec3(x1, y1, base_z)});
  m.triangles.push_back({i, i + 1, i + 2});
  m.triangles.push_back({i + 3, i + 4, i + 5});
  return m;
}

std::unique_ptr<World> BuildFacility() {
  auto world = std::make_unique<World>();
  world->name = "facility";
  Terrain& t = world->terrain;

  // Flat ground in 50 m tiles, 10 m beyond the barrier.
  t.AddMesh(HeightfieldMesh("ground", SurfaceKind::kGround, Range(-300, 300, 50),
                            Range(-200, 200, 50), [](double, double) { return 0.0; }));

  // 1 - test road with obstacles.
  std::vector<double> road_ys = {kRoadY - kRoadHalfWidth - 0.4, kRoadY - kRoadHalfWidth - 0.2,
                                 kRoadY - kRoadHalfWidth, kRoadY + kRoadHalfWidth,
                                 kRoadY + kRoadHalfWidth + 0.2, kRoadY + kRoadHalfWidth + 0.4};
  std::vector<double> road_xs = {-kRoadX - 0.4, -kRoadX - 0.2};
  for (double x : Range(-kRoadX, kRoadX, 4.0)) road_xs.push_back(x);
  road_xs.push_back(kRoadX + 0.2);
  road_xs.push_back(kRoadX + 0.4);
  t.AddMesh(HeightfieldMesh("test_road", SurfaceKind::kRoad, road_xs, road_ys, RoadHeight));
  const double lane_lo = kRoadY - kRoadHalfWidth + 0.2, lane_hi = kRoadY + kRoadHalfWidth - 0.2;
  for (double x0 : {-180.0, -160.0, -140.0}) {
    t.AddMesh(Bump("speed_bump_" + std::to_string(static_cast<int>(-x0)), x0, 0.9, 0.07, lane_lo,
                   lane_hi));
  }
  t.AddMesh(HeightfieldMesh("washboard", SurfaceKind::kObstacle, Range(-100.0, -80.0, 0.1),
                            {lane_lo, lane_hi}, [](double x, double) {
                              return kRoadZ + 0.01 * (1.0 - std::cos(2.0 * std::numbers::pi *
                                                                     (x + 100.0) / 0.8));
                            }));
  t.AddMesh(Bump("one_sided_bump", -40.0, 1.5, 0.10, kRoadY, lane_hi));

  // 3 - jump ramps: A on the road, B on open ground.
  t.AddMesh(Ramp("jump_ramp_a", 40.0, kRoadY - 3.0, kRoadY + 3.0, 10.0, 0.8, kRoadZ));
  t.AddMesh(Ramp("jump_ramp_b", 120.0, -70.0, -64.0, 15.0, 1.2, 0.0));

  // 2 - rough terrain: value noise in three octaves, tapered to the ground over 6 m.
  t.AddMesh(HeightfieldMesh(
      "rough_terrain", SurfaceKind::kRough, Range(-60, 60, 0.5), Range(-10, 90, 0.5),
      [](double x, double y) {
        const double edge = std::min({x + 60.0, 60.0 - x, y + 10.0, 90.0 - y});
        const double taper = SmoothStep(0.0, 6.0, edge);
        const double n = 0.55 * ValueNoise(x / 6.0, y / 6.0, 11) +
                         0.30 * ValueNoise(x / 2.5, y / 2.5, 23) +
                         0.15 * ValueNoise(x / 1.2, y / 1.2, 37);
        return taper * 0.3 * (0.5 + 0.5 * n);
      }));

  // 4 - glass barrier around it all, and the billboard.
  TriangleMesh barrier;
  barrier.name = "glass_barrier";
  barrier.kind = SurfaceKind::kBarrier;
  const double bx = kBarrierX, by = kBarrierY, th = kBarrierThickness, bh = kBarrierHeight;
  barrier.AddBox(Vec3(-bx - th, by, 0), Vec3(bx + th, by + th, bh));     // north
  barrier.AddBox(Vec3(-bx - th, -by - th, 0), Vec3(bx + th, -by, bh));   // south
  barrier.AddBox(Vec3(bx, -by, 0), Vec3(bx + th, by, bh));               // east
  barrier.AddBox(Vec3(-bx - th, -by, 0), Vec3(-bx, by, bh));             // west
  t.AddMesh(std::move(barrier));
  TriangleMesh billboard;
  billboard.name = "billboard";
  billboard.kind = SurfaceKind::kProp;
  billboard.AddBox(Vec3(-3.65, 169.95, 0), Vec3(-3.35, 170.25, 6.0));
  billboard.AddBox(Vec3(3.35, 169.95, 0), Vec3(3.65, 170.25, 6.0));
  billboard.AddBox(Vec3(-4.5, 170.0, 3.0), Vec3(4.5, 170.2, 6.0));
  t.AddMesh(std::move(billboard));
  t.Commit();

  world->spawn = {-250.0, kRoadY, 0.0};
  world->landmarks = {
      {"road_start", Vec3(-250.0, kRoadY, kRoadZ)},
      {"speed_bumps", Vec3(-180.0, kRoadY, kRoadZ)},
      {"washboard", Vec3(-100.0, kRoadY, kRoadZ)},
      {"one_sided_bump", Vec3(-40.0, kRoadY, kRoadZ)},
      {"jump_ramp_a", Vec3(40.0, kRoadY, kRoadZ)},
      {"jump_ramp_b", Vec3(120.0, -67.0, 0.0)},
      {"rough_terrain_center", Vec3(0.0, 40.0, 0.0)},
      {"rough_terrain_min", Vec3(-60.0, -10.0, 0.0)},
      {"rough_terrain_max", Vec3(60.0, 90.0, 0.0)},
      {"barrier_inner_min", Vec3(-kBarrierX, -kBarrierY, 0.0)},
      {"barrier_inner_max", Vec3(kBarrierX, kBarrierY, kBarrierHeight)},
      {"barrier_thickness", Vec3(kBarrierThickness, kBarrierThickness, 0.0)},
      {"billboard", Vec3(0.0, 170.0, 3.0)},
  };
  return world;
}

std::unique_ptr<World> BuildFlat() {
  auto world = std::make_unique<World>();
  world->name = "flat";
  // 40 km x 40 km in 1 km tiles: endless for any test drive, still exact (planes in double).
  world->terrain.AddMesh(HeightfieldMesh("ground", SurfaceKind::kGround, Range(-20000, 20000, 1000),
                                         Range(-20000, 20000, 1000),
                                         [](double, double) { return 0.0; }));
  world->terrain.Commit();
  world->spawn = {0.0, 0.0, 0.0};
  world->landmarks = {{"origin", Vec3::Zero()}};
  return world;
}

}  // namespace

std::unique_ptr<World> WorldFromMesh(TriangleMesh mesh, const Pose2& spawn) {
  auto world = std::make_unique<World>();
  world->name = mesh.name;
  world->terrain.AddMesh(std::move(mesh));
  world->terrain.Commit();
  world->spawn = spawn;
  return world;
}

std::vector<std::string> BuiltinWorldNames() { return {"facility", "flat"}; }

std::unique_ptr<World> BuildBuiltinWorld(const std::string& name) {
  if (name == "facility") return BuildFacility();
  if (name == "flat") return BuildFlat();
  throw WorldError("unknown built-in world '" + name + "' (facility, flat)");
}

}  // namespace vdyn
