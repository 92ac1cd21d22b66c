// The terrain of a world description as the viewer draws it: each mesh's vertices (float, world
// frame) and triangles, checked first. A description that cannot be drawn - vertex or index counts
// that are not multiples of three, an index past the last vertex, a malformed vehicle geometry, no
// triangle at all - is refused whole, with the mesh and the reason; the viewer counts it and keeps
// the world it had.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "vdyn/viewer/math.h"
#include "vdyn/viewer/scene.h"
#include "vdyn/world.pb.h"

namespace vdyn::viewer {

// Empty when the description can be drawn, else why not ("mesh 'road': index 7 of triangle 2
// points past the last of 6 vertices").
std::string CheckWorld(const pb::WorldDescription& world);

struct TerrainMesh {
  std::string name;
  pb::SurfaceKind kind = pb::SURFACE_GROUND;
  std::vector<float> positions_W;  // x, y, z per vertex
  std::vector<std::uint32_t> indices;
};

struct TerrainData {
  std::string name;
  std::vector<TerrainMesh> meshes;
  Vec3 min_W, max_W;  // bounds of every vertex
  std::size_t triangles = 0;
};

// The drawable terrain of a description that passed CheckWorld.
TerrainData TerrainFromWorld(const pb::WorldDescription& world);

// Colours by surface kind (unknown kinds are drawn as ground); the glass barrier is translucent.
struct SurfaceLook {
  Rgb8 colour;
  float alpha = 1.0f;
};
SurfaceLook LookOf(pb::SurfaceKind kind);

}  // namespace vdyn::viewer
