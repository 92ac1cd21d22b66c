// A generated 1-million-triangle terrain for the benchmarks: rolling hills with small bumps.
//
// A square heightfield of 708 x 708 vertices at 0.5 m spacing (353.5 m a side, centred on the
// origin), two triangles per cell: 707 * 707 * 2 = 999,698 triangles. Heights are sums of sines
// (hills) plus integer-hashed value noise (bumps): the same mesh on every machine and compiler.
#pragma once

#include <memory>

#include "vdyn/physics/mesh.h"
#include "vdyn/physics/world.h"

namespace vdyn::bench {

struct TerrainSpec {
  int vertices_per_side = 708;
  double spacing = 0.5;  // m
  double half_size() const { return 0.5 * (vertices_per_side - 1) * spacing; }
};

// The surface the mesh samples at its vertices, m (the mesh is linear in between).
double TerrainHeight(double x, double y);

TriangleMesh GenerateTerrainMesh(const TerrainSpec& spec = {});

// The 1M-triangle terrain as a world, built once per process (Embree's build takes seconds).
std::shared_ptr<const World> GeneratedTerrainWorld();

// The built-in "facility" world, built once per process.
std::shared_ptr<const World> FacilityWorld();

}  // namespace vdyn::bench
