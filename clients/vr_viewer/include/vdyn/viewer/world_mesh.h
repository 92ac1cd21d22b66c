// The terrain of a world description as the viewer draws it, checked first. A description that
// cannot be drawn - vertex or index counts that are not multiples of three, an index past the last
// vertex, a malformed vehicle geometry, no triangle at all - is refused whole, with the mesh and
// the reason; the viewer counts it and keeps the world it had.
//
// Each mesh becomes a surface that reads as what it is (SurfaceStyle, from its kind and shape):
// smooth normals (creased at 40 degrees, so bumps shade round and boxes keep their edges), its
// strip frame (a road's along / across, for lane markings and kerbs; the distance to its edge,
// where rough ground blends into the grass), and chunks of 32 m with their bounds, so what is out
// of sight or out of the sun's shadow box is not drawn. A large mesh (a fine heightfield) has
// coarser versions of each chunk for far away: its vertices merged in cells of 1 m and 4 m.
#pragma once

#include <array>
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

// How a surface is shaded (renderer.cc):
enum class SurfaceStyle {
  kGrass,     // ground
  kAsphalt,   // road: lane markings and red-and-white kerbs along a strip
  kHazard,    // a short obstacle (a speed bump): yellow and black paint
  kConcrete,  // a long obstacle (washboard), ramps
  kDirt,      // rough ground: dirt and gravel, blending into the grass at its edge
  kGlass,     // the barrier: translucent, with posts and a top rail
  kPainted,   // props: painted steel
};

// A mesh's frame on the ground: its long axis (from the spread of its vertices), the centre line
// and extent. A road is a strip when it is at least three times as long as wide and at most 40 m
// wide: then it gets lane markings and kerbs.
struct StripFrame {
  Vec3 centre_W;             // on the centre line, z = 0
  Vec3 along_W{1, 0, 0};     // unit, in the XY plane
  double half_length_m = 0;  // from the centre along
  double half_width_m = 0;   // from the centre line across
  bool strip = false;
};

struct TerrainVertex {
  float p[3];  // world, m
  float n[3];  // unit normal
};
static_assert(sizeof(TerrainVertex) == 24);

// Levels of detail: all triangles; vertices merged in cells of kLodCellM[1], of kLodCellM[2].
inline constexpr int kTerrainLods = 3;
inline constexpr double kLodCellM[kTerrainLods] = {0.0, 1.0, 4.0};
// From how far (m, eye to the chunk's box) a level is drawn.
inline constexpr double kLodFromM[kTerrainLods] = {0.0, 30.0, 120.0};

struct TerrainChunk {
  struct Range {
    std::uint32_t first = 0, count = 0;  // in TerrainMesh::indices
  };
  std::array<Range, kTerrainLods> lods;  // a small mesh: the same range in each
  Vec3 min_W, max_W;
};

// A prop's face that carries the billboard's poster (textures.h): its largest vertical flat face
// that looks towards the middle of the world - a rectangle from its lower left corner (seen from
// the front) `right_W` (unit, horizontal) `width_m` wide and `height_m` high (up).
struct PosterFace {
  Vec3 origin_W, right_W{1, 0, 0};
  double width_m = 0, height_m = 0;
  bool present = false;
};

struct TerrainMesh {
  std::string name;
  pb::SurfaceKind kind = pb::SURFACE_GROUND;
  SurfaceStyle style = SurfaceStyle::kGrass;
  StripFrame frame;
  std::vector<TerrainVertex> vertices;
  std::vector<std::uint32_t> indices;  // grouped by chunk
  std::vector<TerrainChunk> chunks;
  Vec3 min_W, max_W;
  PosterFace poster;  // props (SurfaceStyle::kPainted) with a face of at least 4 m2
};

// The poster face of a mesh's vertices and triangles, facing towards `towards_W`; none when no
// vertical flat face is as large as `min_area_m2`.
PosterFace PosterFaceOf(const std::vector<TerrainVertex>& vertices,
                        const std::vector<std::uint32_t>& indices, const Vec3& towards_W,
                        double min_area_m2 = 4.0);

struct TerrainData {
  std::string name;
  std::vector<TerrainMesh> meshes;
  Vec3 min_W, max_W;  // bounds of every vertex
  // Bounds of the ground meshes (the grass beyond them is drawn to the horizon).
  Vec3 ground_min_W, ground_max_W;
  bool has_ground = false;
  std::size_t triangles = 0;
};

// The drawable terrain of a description that passed CheckWorld.
TerrainData TerrainFromWorld(const pb::WorldDescription& world);

// The style of a mesh of a kind with a frame (obstacles: short ones are painted bumps).
SurfaceStyle StyleOf(pb::SurfaceKind kind, const StripFrame& frame);
StripFrame FrameOf(const std::vector<Vec3>& points_W);

// How a surface looks from afar (its texture's mean, the markings left out) and whether it is
// translucent (the glass barrier). Unknown kinds are drawn as ground.
struct SurfaceLook {
  Rgb8 colour;
  float alpha = 1.0f;
};
SurfaceLook LookOf(pb::SurfaceKind kind);

// The road's markings (docs in the viewer's README), across from a strip's centre line, m: the
// kerbs take the outer 0.45 m, the edge lines (0.15 m wide) lie 0.75 m inside the edge, the
// centre line is dashed, 3 m in 12 m. Kerb blocks are 1 m long, red and white.
struct RoadMarkings {
  static constexpr double kKerbWidth = 0.45, kKerbBlock = 1.0;
  static constexpr double kEdgeLineInset = 0.75, kLineWidth = 0.15;
  static constexpr double kDash = 3.0, kDashPeriod = 12.0;
};

}  // namespace vdyn::viewer
