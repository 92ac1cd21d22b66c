// The dressing around a facility, so the world reads as a place: trees in clumps, a grandstand and
// a pit building facing the longest road, signs along the barrier, and a ring of far hills. It is
// made from the world description alone (no placement numbers of a particular world) and only
// where no vehicle can reach: beyond the outer face of the world's glass barrier (its meshes of
// kind SURFACE_BARRIER), when that barrier closes around every drivable mesh. A world without
// such a barrier (`flat`, a file's open terrain) gets none: a vehicle could drive anywhere on it,
// and nothing a driver sees may be something the car would drive through.
//
//        hills (a ring, 250 m .. 1150 m beyond the barrier's corners)
//    trees  trees  trees  trees  trees        (clumps, from kTreeBandFromM out)
//    [sign]   [sign]   [sign]   [sign]        (kSignOutM beyond the outer face)
//   ===================== glass barrier ======================
//            the facility: nothing is placed here
//   ===================== glass barrier ======================
//    [sign]  [grandstand]  [pit building]     (on the side nearest the longest road)
//    trees  trees  trees
#pragma once

#include <cstdint>
#include <vector>

#include "vdyn/viewer/draw_list.h"
#include "vdyn/viewer/math.h"
#include "vdyn/viewer/world_mesh.h"

namespace vdyn::viewer {

// How far beyond the barrier's outer face (m) the nearest dressing stands.
inline constexpr double kDressingClearanceM = 2.0;
// A barrier longer than this on a side (m) gets no dressing: the trees and signs along it would
// grow with its length (a 10,000 km box in a description must not cost minutes and gigabytes).
inline constexpr double kMaxDressedSideM = 5000.0;

// A part of the dressing's triangles (vertices [first, first + count) of the list) with the
// bounds of its vertices: what is out of view is not drawn.
struct DressingChunk {
  std::uint32_t first = 0, count = 0;
  Vec3 min_W, max_W;
};

struct Dressing {
  DrawList list;  // lit triangles with their colours (the landmarks' program draws them)
  std::vector<DressingChunk> chunks;
  // The region a vehicle can reach: the barrier's outer bounds (z: its foot to its top). Nothing
  // of the dressing lies within it grown by kDressingClearanceM.
  Vec3 reach_min_W, reach_max_W;
  bool enclosed = false;  // a closed barrier around every drivable mesh: dressing was placed
  std::size_t trees = 0;  // how many (for the quality's budget and the tests)
};

// `full` (quality high): every tree of the clumps and the hills; else under a third of the trees,
// in a narrower band, and no hills (a software renderer's budget: the sky's far hills remain).
Dressing MakeDressing(const TerrainData& t, bool full);

// Whether the barrier meshes close around the drivable ones: each side of their bounds is covered
// (98 % of its length) by barrier triangles lying within 1 m of it, and every mesh other than the
// ground lies inside those bounds. Writes the bounds.
bool BarrierEncloses(const TerrainData& t, Vec3* min_W, Vec3* max_W);

}  // namespace vdyn::viewer
