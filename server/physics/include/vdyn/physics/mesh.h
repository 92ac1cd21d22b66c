// Triangle meshes: the terrain's source geometry (worlds, imported files), kept in double.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace vdyn {

// Surface kinds, for viewers and for reports; physics treats every triangle alike.
enum class SurfaceKind : std::uint8_t { kGround, kRoad, kObstacle, kRough, kRamp, kBarrier, kProp };

struct TriangleMesh {
  std::string name;
  SurfaceKind kind = SurfaceKind::kGround;
  std::vector<Eigen::Vector3d> vertices_W;                 // world frame, m
  std::vector<std::array<std::uint32_t, 3>> triangles;     // counter-clockwise seen from outside

  // Appends a quad (a, b, c, d counter-clockwise) as two triangles.
  void AddQuad(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
               const Eigen::Vector3d& d);
  // Appends an axis-aligned box [lo, hi] (closed, outward faces).
  void AddBox(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi);
  // Appends another mesh's triangles.
  void Append(const TriangleMesh& other);
};

}  // namespace vdyn
