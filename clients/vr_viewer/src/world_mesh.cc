#include "vdyn/viewer/world_mesh.h"

#include <algorithm>
#include <limits>

namespace vdyn::viewer {

std::string CheckWorld(const pb::WorldDescription& world) {
  std::size_t triangles = 0;
  for (int m = 0; m < world.meshes_size(); ++m) {
    const pb::Mesh& mesh = world.meshes(m);
    const std::string where = "mesh '" + mesh.name() + "' (" + std::to_string(m) + ")";
    if (mesh.vertices_size() % 3 != 0) {
      return where + ": " + std::to_string(mesh.vertices_size()) +
             " vertex coordinates, not a multiple of 3";
    }
    if (mesh.indices_size() % 3 != 0) {
      return where + ": " + std::to_string(mesh.indices_size()) +
             " indices, not a multiple of 3 (three per triangle)";
    }
    const auto vertices = static_cast<std::uint64_t>(mesh.vertices_size() / 3);
    for (int i = 0; i < mesh.indices_size(); ++i) {
      if (mesh.indices(i) >= vertices) {
        return where + ": index " + std::to_string(mesh.indices(i)) + " of triangle " +
               std::to_string(i / 3) + " points past the last of " + std::to_string(vertices) +
               " vertices";
      }
    }
    triangles += static_cast<std::size_t>(mesh.indices_size() / 3);
  }
  if (triangles == 0) return "world '" + world.name() + "' holds no triangle";
  for (const pb::VehicleGeometry& g : world.vehicles()) {
    std::string why = CheckGeometry(g);
    if (!why.empty()) return why;
  }
  return {};
}

TerrainData TerrainFromWorld(const pb::WorldDescription& world) {
  TerrainData t;
  t.name = world.name();
  constexpr double kBig = std::numeric_limits<double>::max();
  t.min_W = {kBig, kBig, kBig};
  t.max_W = {-kBig, -kBig, -kBig};
  t.meshes.reserve(static_cast<std::size_t>(world.meshes_size()));
  for (const pb::Mesh& mesh : world.meshes()) {
    if (mesh.indices_size() == 0) continue;
    TerrainMesh& m = t.meshes.emplace_back();
    m.name = mesh.name();
    m.kind = mesh.kind();
    m.positions_W.resize(static_cast<std::size_t>(mesh.vertices_size()));
    for (int i = 0; i + 2 < mesh.vertices_size(); i += 3) {
      const double x = mesh.vertices(i), y = mesh.vertices(i + 1), z = mesh.vertices(i + 2);
      const auto k = static_cast<std::size_t>(i);
      m.positions_W[k] = static_cast<float>(x);
      m.positions_W[k + 1] = static_cast<float>(y);
      m.positions_W[k + 2] = static_cast<float>(z);
      t.min_W = {std::min(t.min_W.x, x), std::min(t.min_W.y, y), std::min(t.min_W.z, z)};
      t.max_W = {std::max(t.max_W.x, x), std::max(t.max_W.y, y), std::max(t.max_W.z, z)};
    }
    m.indices.assign(mesh.indices().begin(), mesh.indices().end());
    t.triangles += m.indices.size() / 3;
  }
  if (t.meshes.empty()) t.min_W = t.max_W = Vec3{};
  return t;
}

SurfaceLook LookOf(pb::SurfaceKind kind) {
  switch (kind) {
    case pb::SURFACE_ROAD:
      return {{72, 74, 80}, 1.0f};
    case pb::SURFACE_OBSTACLE:
      return {{190, 160, 90}, 1.0f};
    case pb::SURFACE_ROUGH:
      return {{128, 104, 78}, 1.0f};
    case pb::SURFACE_RAMP:
      return {{165, 170, 185}, 1.0f};
    case pb::SURFACE_BARRIER:
      return {{170, 225, 240}, 0.35f};
    case pb::SURFACE_PROP:
      return {{215, 205, 190}, 1.0f};
    case pb::SURFACE_GROUND:
    default:
      return {{128, 146, 112}, 1.0f};
  }
}

}  // namespace vdyn::viewer
