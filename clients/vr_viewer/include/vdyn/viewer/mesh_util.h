// Triangle meshes made ready for lighting: positions welded, normals averaged over the faces that
// meet at a vertex, except across a crease (faces turned by more than `crease_deg` keep their own
// normal there). A heightfield's bumps then shade round while a box or a ramp keeps its edges.
// Used for the terrain (world_mesh.cc) and the car bodies (car_model.cc).
#pragma once

#include <cstdint>
#include <vector>

#include "vdyn/viewer/math.h"

namespace vdyn::viewer {

struct SmoothedMesh {
  std::vector<Vec3> positions;
  std::vector<Vec3> normals;         // unit
  std::vector<std::uint32_t> group;  // the group of the faces a vertex came from
  std::vector<std::uint32_t> indices;
  // For each output triangle, the input triangle it came from (degenerate ones are dropped).
  std::vector<std::uint32_t> source_triangle;
};

// `positions` with three `indices` per triangle; `triangle_group` (optional, one per triangle)
// keeps vertices of different groups (materials) apart even where they coincide.
SmoothedMesh SmoothNormals(const std::vector<Vec3>& positions,
                           const std::vector<std::uint32_t>& indices,
                           const std::vector<std::uint32_t>& triangle_group, double crease_deg);

}  // namespace vdyn::viewer
