// Terrain traces and the built-in worlds.
#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "test_support.h"
#include "vdyn/physics/world.h"

namespace vdyn {
namespace {

using Eigen::Vector3d;

TEST(Terrain, VerticalTraceOnFlatGroundIsExactInDouble) {
  const auto world = testing::SharedWorld("flat");
  // Far from the origin and off any float grid: the plane refinement keeps full precision.
  for (const double x : {0.0, 123.456789, 4321.123456789}) {
    const double z0 = 0.5 + 1e-9;
    const TraceHit hit = world->terrain.Trace(Vector3d(x, -77.7, z0), -Vector3d::UnitZ(), 2.0);
    ASSERT_TRUE(hit.hit);
    EXPECT_NEAR(hit.distance, z0, 1e-14) << "x = " << x;
    EXPECT_EQ(hit.normal_W, Vector3d::UnitZ());
  }
}

TEST(Terrain, SlantedTraceAndRangeLimit) {
  const auto world = testing::SharedWorld("flat");
  const Vector3d dir = Vector3d(1.0, 0.0, -1.0).normalized();
  const TraceHit hit = world->terrain.Trace(Vector3d(0, 0, 1.0), dir, 10.0);
  ASSERT_TRUE(hit.hit);
  EXPECT_NEAR(hit.distance, std::sqrt(2.0), 1e-12);
  EXPECT_FALSE(world->terrain.Trace(Vector3d(0, 0, 1.0), dir, 1.4).hit);
  EXPECT_FALSE(world->terrain.Trace(Vector3d(0, 0, 1.0), Vector3d::UnitZ(), 100.0).hit);
}

TEST(Terrain, NormalFacesTheRayOriginFromEitherSide) {
  const auto world = testing::SharedWorld("flat");
  const TraceHit below = world->terrain.Trace(Vector3d(0, 0, -1.0), Vector3d::UnitZ(), 5.0);
  ASSERT_TRUE(below.hit);
  EXPECT_NEAR(below.distance, 1.0, 1e-12);
  EXPECT_EQ(below.normal_W, -Vector3d::UnitZ());
}

TEST(Terrain, DegenerateAndNonFiniteTrianglesAreDroppedAndCounted) {
  Terrain t;
  TriangleMesh m;
  m.name = "mixed";
  m.vertices_W = {Vector3d(0, 0, 0), Vector3d(1, 0, 0), Vector3d(0, 1, 0), Vector3d(2, 0, 0),
                  Vector3d(std::numeric_limits<double>::quiet_NaN(), 0, 0)};
  m.triangles = {{0, 1, 2}, {0, 1, 3}, {0, 1, 4}};  // good, collinear, NaN
  t.AddMesh(m);
  t.Commit();
  EXPECT_EQ(t.triangle_count(), 1u);
  EXPECT_EQ(t.dropped_triangles(), 2u);
  EXPECT_TRUE(t.Trace(Vector3d(0.2, 0.2, 1), -Vector3d::UnitZ(), 2).hit);
}

TEST(Terrain, IndexOutOfRangeIsRefused) {
  Terrain t;
  TriangleMesh m;
  m.name = "broken";
  m.vertices_W = {Vector3d(0, 0, 0), Vector3d(1, 0, 0), Vector3d(0, 1, 0)};
  m.triangles = {{0, 1, 7}};
  EXPECT_THROW(t.AddMesh(m), std::invalid_argument);
}

TEST(Facility, HasThePapersPartsAndTheyAreWhereTheLandmarksSay) {
  const auto world = testing::SharedWorld("facility");
  std::set<std::string> names;
  for (const auto& m : world->terrain.meshes()) names.insert(m.name);
  for (const char* part : {"ground", "test_road", "washboard", "jump_ramp_a", "jump_ramp_b",
                           "rough_terrain", "glass_barrier", "billboard"}) {
    EXPECT_TRUE(names.count(part)) << part;
  }
  const Terrain& t = world->terrain;
  auto ground_z = [&t](double x, double y) {
    const TraceHit h = t.Trace(Vector3d(x, y, 50.0), -Vector3d::UnitZ(), 100.0);
    EXPECT_TRUE(h.hit);
    return 50.0 - h.distance;
  };
  // The ramp's top edge is 0.8 m above the road, the road 2 cm above the ground.
  const Vector3d ramp = world->LandmarkAt("jump_ramp_a");
  EXPECT_NEAR(ground_z(ramp.x() + 0.8 / std::tan(10.0 * M_PI / 180.0) - 0.01, ramp.y()), 0.82,
              0.01);
  EXPECT_NEAR(ground_z(0.0, ramp.y()), 0.02, 1e-9);
  EXPECT_NEAR(ground_z(200.0, 100.0), 0.0, 1e-12);
  // The rough terrain is rough: its heights spread over more than 10 cm.
  const Vector3d c = world->LandmarkAt("rough_terrain_center");
  double lo = 1e9, hi = -1e9;
  for (int i = -20; i <= 20; ++i) {
    const double z = ground_z(c.x() + i * 1.3, c.y() + i * 0.7);
    lo = std::min(lo, z);
    hi = std::max(hi, z);
  }
  EXPECT_GT(hi - lo, 0.1);
  // A horizontal trace from inside finds the glass barrier at the landmark's distance.
  const Vector3d inner = world->LandmarkAt("barrier_inner_max");
  const TraceHit wall = t.Trace(Vector3d(100.0, inner.y() - 5.0, 0.5), Vector3d::UnitY(), 10.0);
  ASSERT_TRUE(wall.hit);
  EXPECT_NEAR(wall.distance, 5.0, 1e-9);
  EXPECT_EQ(t.meshes()[wall.mesh].name, "glass_barrier");
  EXPECT_EQ(wall.normal_W, -Vector3d::UnitY());
}

TEST(Facility, IsLargeEnoughToDriveForMinutes) {
  // Measure the enclosure with horizontal traces from its middle (above the rough terrain's and
  // the ramps' height, below the billboard) and check it against the landmarks.
  const auto world = testing::SharedWorld("facility");
  const Terrain& t = world->terrain;
  const Vector3d o(150.0, 0.0, 1.0);
  double reach[4];
  const Vector3d dirs[4] = {Vector3d::UnitX(), -Vector3d::UnitX(), Vector3d::UnitY(),
                            -Vector3d::UnitY()};
  for (int i = 0; i < 4; ++i) {
    const TraceHit h = t.Trace(o, dirs[i], 2000.0);
    ASSERT_TRUE(h.hit) << i;
    EXPECT_EQ(t.meshes()[h.mesh].name, "glass_barrier") << i;
    reach[i] = h.distance;
  }
  const double width = reach[0] + reach[1], depth = reach[2] + reach[3];
  const Vector3d lo = world->LandmarkAt("barrier_inner_min");
  const Vector3d hi = world->LandmarkAt("barrier_inner_max");
  EXPECT_NEAR(width, hi.x() - lo.x(), 1e-9);
  EXPECT_NEAR(depth, hi.y() - lo.y(), 1e-9);
  // Once around inside the barrier at 50 km/h takes more than two minutes.
  EXPECT_GT(2.0 * (width + depth) / (50.0 / 3.6), 120.0);
}

TEST(Terrain, PacketTraceAnswersLikeSingleTraces) {
  const auto world = testing::SharedWorld("facility");
  const Terrain& t = world->terrain;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::array<Vector3d, 4> origins = {Vector3d(10.3, 40.7, 2.0), Vector3d(42.0, -150.2, 3.0),
                                           Vector3d(0, 0, nan), Vector3d(100.0, 100.0, 0.5)};
  const std::array<Vector3d, 4> dirs = {-Vector3d::UnitZ(), -Vector3d::UnitZ(), -Vector3d::UnitZ(),
                                        Vector3d::UnitZ()};
  const std::array<double, 4> ranges = {5.0, 5.0, 5.0, 5.0};
  std::array<TraceHit, 4> hits;
  t.Trace4(origins, dirs, ranges, hits);
  for (int i = 0; i < 4; ++i) {
    const TraceHit one = t.Trace(origins[i], dirs[i], ranges[i]);
    EXPECT_EQ(hits[i].hit, one.hit) << i;
    EXPECT_EQ(hits[i].distance, one.distance) << i;
    EXPECT_EQ(hits[i].normal_W, one.normal_W) << i;
  }
  EXPECT_TRUE(hits[0].hit);   // rough terrain
  EXPECT_TRUE(hits[1].hit);   // jump ramp A
  EXPECT_FALSE(hits[2].hit);  // non-finite origin: no hit, no crash
  // Finite in double but not as a float, and absurd ranges: no hit, no crash either.
  const std::array<Vector3d, 4> huge = {Vector3d(1e300, 0, 1), Vector3d(0, 0, 1),
                                        Vector3d(0, 0, 1), Vector3d(0, 0, 1)};
  const std::array<Vector3d, 4> bad_dirs = {-Vector3d::UnitZ(), Vector3d(0, 0, -1e200),
                                            Vector3d::Zero(), -Vector3d::UnitZ()};
  const std::array<double, 4> bad_ranges = {5.0, 5.0, 5.0, 1e300};
  t.Trace4(huge, bad_dirs, bad_ranges, hits);
  for (const TraceHit& h : hits) EXPECT_FALSE(h.hit);
  EXPECT_FALSE(t.Trace(huge[0], -Vector3d::UnitZ(), 5.0).hit);
  EXPECT_FALSE(hits[3].hit);  // upwards into the sky
}

TEST(Terrain, SteepSurfaceGridFindsWallsNearAndNothingInTheOpen) {
  const auto world = testing::SharedWorld("facility");
  const Terrain& t = world->terrain;
  const Vector3d inner = world->LandmarkAt("barrier_inner_max");
  EXPECT_TRUE(t.SteepSurfaceNear(100.0, inner.y() - 3.0, 4.0));
  EXPECT_TRUE(t.SteepSurfaceNear(inner.x() - 1.0, 0.0, 2.0));
  EXPECT_TRUE(t.SteepSurfaceNear(0.0, 170.0, 1.0));  // billboard posts
  // Conservative: every vertical face of the facility is flagged within its own cell.
  for (const auto& mesh : t.meshes()) {
    for (const auto& tri : mesh.triangles) {
      const Vector3d a = mesh.vertices_W[tri[0]], b = mesh.vertices_W[tri[1]],
                     c = mesh.vertices_W[tri[2]];
      const Vector3d n = (b - a).cross(c - a).normalized();
      if (std::abs(n.z()) < Terrain::kSteepNormalZ) {
        const Vector3d m = (a + b + c) / 3.0;
        ASSERT_TRUE(t.SteepSurfaceNear(m.x(), m.y(), 0.0)) << mesh.name;
      }
    }
  }
  EXPECT_FALSE(t.SteepSurfaceNear(200.0, 100.0, 6.0));  // open ground
  EXPECT_FALSE(testing::SharedWorld("flat")->terrain.SteepSurfaceNear(0.0, 0.0, 100.0));
}

TEST(Worlds, UnknownBuiltinIsAClearError) {
  EXPECT_THROW(BuildBuiltinWorld("moon"), WorldError);
}

}  // namespace
}  // namespace vdyn
