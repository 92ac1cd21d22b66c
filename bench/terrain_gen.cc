#include "terrain_gen.h"

#include <cmath>
#include <cstdint>
#include <numbers>

namespace vdyn::bench {
namespace {

// SplitMix64's finaliser on the lattice point: a well-mixed value in [-1, 1).
double LatticeValue(std::int64_t i, std::int64_t j) {
  std::uint64_t h = static_cast<std::uint64_t>(i) * 0x9E3779B97F4A7C15ull ^
                    static_cast<std::uint64_t>(j) * 0xD1B54A32D192ED03ull;
  h = (h ^ (h >> 30)) * 0xBF58476D1CE4E5B9ull;
  h = (h ^ (h >> 27)) * 0x94D049BB133111EBull;
  h ^= h >> 31;
  return static_cast<double>(h >> 11) * 0x1.0p-52 - 1.0;
}

// Value noise: lattice values blended with a smoothstep, continuous with a continuous slope.
double ValueNoise(double x, double y) {
  const double fx = std::floor(x), fy = std::floor(y);
  const auto i = static_cast<std::int64_t>(fx), j = static_cast<std::int64_t>(fy);
  const double tx = (x - fx) * (x - fx) * (3.0 - 2.0 * (x - fx));
  const double ty = (y - fy) * (y - fy) * (3.0 - 2.0 * (y - fy));
  const double a = LatticeValue(i, j), b = LatticeValue(i + 1, j);
  const double c = LatticeValue(i, j + 1), d = LatticeValue(i + 1, j + 1);
  return (a + (b - a) * tx) * (1.0 - ty) + (c + (d - c) * tx) * ty;
}

}  // namespace

double TerrainHeight(double x, double y) {
  constexpr double k2Pi = 2.0 * std::numbers::pi;
  // Hills: wavelengths 37-120 m, heights within +-2.7 m; with the bumps the steepest triangle is
  // 15 degrees, which the car climbs at 15 m/s on its speed control.
  const double hills = 1.5 * std::sin(k2Pi * x / 120.0) * std::cos(k2Pi * y / 97.0) +
                       0.8 * std::sin(k2Pi * (x + y) / 70.0 + 0.7) +
                       0.4 * std::cos(k2Pi * (x - 0.5 * y) / 37.0);
  // Bumps: +-4 cm on a 1.5 m lattice, a few vertices per bump so the wheels feel them.
  const double bumps = 0.04 * ValueNoise(x / 1.5, y / 1.5);
  return hills + bumps;
}

TriangleMesh GenerateTerrainMesh(const TerrainSpec& spec) {
  TriangleMesh m;
  m.name = "terrain_1m";
  m.kind = SurfaceKind::kRough;
  const auto n = static_cast<std::uint32_t>(spec.vertices_per_side);
  const double x0 = -spec.half_size();
  m.vertices_W.reserve(static_cast<std::size_t>(n) * n);
  for (std::uint32_t j = 0; j < n; ++j) {
    for (std::uint32_t i = 0; i < n; ++i) {
      const double x = x0 + spec.spacing * i, y = x0 + spec.spacing * j;
      m.vertices_W.emplace_back(x, y, TerrainHeight(x, y));
    }
  }
  m.triangles.reserve(2 * static_cast<std::size_t>(n - 1) * (n - 1));
  for (std::uint32_t j = 0; j + 1 < n; ++j) {
    for (std::uint32_t i = 0; i + 1 < n; ++i) {
      const std::uint32_t a = j * n + i, b = a + 1, c = a + n + 1, d = a + n;
      m.triangles.push_back({a, b, c});  // counter-clockwise seen from above
      m.triangles.push_back({a, c, d});
    }
  }
  return m;
}

std::shared_ptr<const World> GeneratedTerrainWorld() {
  static const std::shared_ptr<const World> world =
      WorldFromMesh(GenerateTerrainMesh(), Pose2{0.0, 0.0, 0.0});
  return world;
}

std::shared_ptr<const World> FacilityWorld() {
  static const std::shared_ptr<const World> world = BuildBuiltinWorld("facility");
  return world;
}

}  // namespace vdyn::bench
