// Terrain: triangle meshes in an Embree 3 scene (robust mode) and the line traces the model uses.
//
// Embree finds the hit triangle in single precision; the hit distance and normal are then
// recomputed in double against that triangle's plane, so a trace is smooth in the ray origin
// (no float staircase) and exact on planar ground far from the origin.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "vdyn/physics/mesh.h"

namespace vdyn {

struct TraceHit {
  bool hit = false;
  double distance = 0;                                    // along the unit direction, m
  Eigen::Vector3d normal_W = Eigen::Vector3d::UnitZ();    // unit, facing the ray's origin
  std::uint32_t mesh = 0;                                  // index into Terrain::meshes()
  std::uint32_t triangle = 0;
};

class Terrain {
 public:
  Terrain();
  ~Terrain();
  Terrain(const Terrain&) = delete;
  Terrain& operator=(const Terrain&) = delete;

  // Adds a mesh; triangles with a vertex that is not finite or beyond 1e9 m (Embree works in
  // single precision), or with zero area, are dropped and counted.
  // Throws std::invalid_argument for an index out of range. Only before Commit().
  void AddMesh(TriangleMesh mesh);
  // Builds the acceleration structure. After this the terrain is immutable and traces may run
  // concurrently from several threads.
  void Commit();

  // Closest hit along origin + t * dir_W (dir_W unit) for t in [0, t_max]. No allocation.
  TraceHit Trace(const Eigen::Vector3d& origin_W, const Eigen::Vector3d& dir_W, double t_max) const;

  // Four traces at once (one Embree ray packet), each as Trace would answer it.
  void Trace4(const std::array<Eigen::Vector3d, 4>& origin_W,
              const std::array<Eigen::Vector3d, 4>& dir_W, const std::array<double, 4>& t_max,
              std::array<TraceHit, 4>& hits) const;

  // The highest surface at (x, y): a vertical trace from above the whole terrain down through
  // it. Its hit's distance is from z = bounds_max().z() + 10 m (ground z = that - distance); no
  // hit where no terrain lies under (x, y).
  TraceHit GroundBelow(double x, double y) const;
  double above_all_z() const { return bounds_max_.z() + 10.0; }

  // Whether any steep surface (|n_z| < kSteepNormalZ: walls, barrier, ramp faces) lies within
  // `radius` of (x, y) in the horizontal plane, from a grid built at Commit. Conservative: it may
  // say yes when the surface is a little farther, never no when it is near.
  bool SteepSurfaceNear(double x, double y, double radius) const;
  static constexpr double kSteepNormalZ = 0.7;

  const std::vector<TriangleMesh>& meshes() const { return meshes_; }
  std::size_t triangle_count() const { return triangle_count_; }
  std::size_t dropped_triangles() const { return dropped_triangles_; }
  Eigen::Vector3d bounds_min() const { return bounds_min_; }
  Eigen::Vector3d bounds_max() const { return bounds_max_; }
  bool committed() const { return committed_; }
  // Errors Embree reported (counted here; the physics logs nothing), and the last one's code.
  std::uint64_t embree_errors() const;
  int last_embree_error() const;

  struct Impl;  // Embree's device and scene

 private:
  // One record per Embree primitive, in one flat array (one cache line per hit).
  struct Plane {
    Eigen::Vector3d n;        // unit normal
    double offset;            // n . x for x on the plane
    std::uint32_t mesh;       // index into meshes_
    std::uint32_t triangle;   // index into that mesh's triangles
  };
  TraceHit Refine(const Eigen::Vector3d& origin_W, const Eigen::Vector3d& dir_W, double t_max,
                  unsigned geom_id, unsigned prim_id, float t_float) const;
  void BuildSteepGrid();

  std::unique_ptr<Impl> impl_;
  std::vector<TriangleMesh> meshes_;
  std::vector<Plane> planes_;               // all meshes' kept triangles
  std::vector<std::uint32_t> geom_base_;     // Embree geometry id -> its first record in planes_
  std::size_t triangle_count_ = 0;
  std::size_t dropped_triangles_ = 0;
  Eigen::Vector3d bounds_min_ = Eigen::Vector3d::Constant(1e300);
  Eigen::Vector3d bounds_max_ = Eigen::Vector3d::Constant(-1e300);
  bool committed_ = false;
  // Steep-surface grid over the terrain's XY bounds: one flag per cell.
  double grid_cell_ = 1.0;
  double grid_x0_ = 0, grid_y0_ = 0;
  int grid_nx_ = 0, grid_ny_ = 0;
  std::vector<std::uint8_t> steep_cells_;
};

}  // namespace vdyn
