#include "rays.h"

#include <cmath>
#include <cstdint>
#include <numbers>

#include "terrain_gen.h"

namespace vdyn::bench {
namespace {

constexpr double kSpacing = 50.0 / 3.6 / 1000.0;  // m travelled per 1 ms at 50 km/h
constexpr double kLift = 0.7;                     // m above the ground

// The wheel-ray origins of a car at (x, y, yaw); false if the ground is missing below a wheel.
bool CarRays(const Terrain& terrain, const Params& p, double x, double y, double yaw,
             std::array<Eigen::Vector3d, 4>& out) {
  const double c = std::cos(yaw), s = std::sin(yaw);
  const double top = terrain.bounds_max().z() + 1.0;
  const double depth = top - terrain.bounds_min().z() + 1.0;
  for (int w = 0; w < 4; ++w) {
    const Eigen::Vector3d& a = p.p_TA_B[w];
    const Eigen::Vector3d o(x + c * a.x() - s * a.y(), y + s * a.x() + c * a.y(), top);
    const TraceHit hit = terrain.Trace(o, -Eigen::Vector3d::UnitZ(), depth);
    if (!hit.hit) return false;
    out[w] = Eigen::Vector3d(o.x(), o.y(), top - hit.distance + kLift);
  }
  return true;
}

// SplitMix64: a deterministic stream of uniform numbers in [0, 1).
struct SplitMix {
  std::uint64_t s = 0x243F6A8885A308D3ull;
  double Next() {
    std::uint64_t z = (s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return static_cast<double>((z ^ (z >> 31)) >> 11) * 0x1.0p-53;
  }
};

}  // namespace

RaySet MovingRays(const Course& course) {
  const Terrain& terrain = course.world->terrain;
  const Params p = BenchParams();
  RaySet set;
  std::array<Eigen::Vector3d, 4> o;
  if (course.name == "facility") {
    for (double x = -250.0; x < 250.0; x += kSpacing) {
      if (CarRays(terrain, p, x, -150.0, 0.0, o)) set.origins.push_back(o);
    }
  } else {
    const double r = 150.0;
    const auto n = static_cast<int>(2.0 * std::numbers::pi * r / kSpacing);
    for (int i = 0; i < n; ++i) {
      const double phi = 2.0 * std::numbers::pi * i / n;
      if (CarRays(terrain, p, r * std::cos(phi), r * std::sin(phi), phi + 0.5 * std::numbers::pi,
                  o)) {
        set.origins.push_back(o);
      }
    }
  }
  return set;
}

RaySet RandomRays(const Course& course) {
  const Terrain& terrain = course.world->terrain;
  const Params p = BenchParams();
  // facility: inside the glass barrier; the generated terrain: away from its edge.
  const double hx = course.name == "facility" ? 285.0 : TerrainSpec{}.half_size() - 5.0;
  const double hy = course.name == "facility" ? 185.0 : hx;
  RaySet set;
  SplitMix rng;
  std::array<Eigen::Vector3d, 4> o;
  while (set.origins.size() < 65536) {
    const double x = hx * (2.0 * rng.Next() - 1.0), y = hy * (2.0 * rng.Next() - 1.0);
    if (CarRays(terrain, p, x, y, 2.0 * std::numbers::pi * rng.Next(), o)) set.origins.push_back(o);
  }
  return set;
}

}  // namespace vdyn::bench
