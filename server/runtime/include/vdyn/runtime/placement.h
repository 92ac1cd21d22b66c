// Where a server's vehicles start: the first at the world's spawn, the others side by side on the
// free ground nearest to it.
//
//
//   left   │ 5 │ 2 │       cells 5 m apart side by side (left first) and 8 m nose to tail,
//          │ 4 │ 1 │ ──►   behind the spawn's row before ahead of it (a vehicle ahead would stand
//   right  │ 6 │ 3 │       in the first one's way); a cell is taken only where a vehicle rests on
//           behind         ground it fits (RestingState, SpawnObstruction)
#pragma once

#include <cstddef>
#include <vector>

#include "vdyn/physics/params.h"
#include "vdyn/physics/world.h"

namespace vdyn {

struct PlacementGrid {
  double across_m = 5.0;   // between columns (side by side)
  double along_m = 8.0;    // between rows (nose to tail)
  double reach_m = 400.0;  // cells whose centre is further from the spawn are not tried
};

// Poses for `n` vehicles with parameters `p`: the world's spawn first, then the free cells of the
// grid nearest to it, those at or behind the spawn's row before those ahead, in a fixed order
// (the same poses for the same world every time). Throws WorldError with the reason when the
// first cannot start at the spawn, and, saying how many fit, when fewer than n cells are free.
std::vector<Pose2> StartPoses(const World& world, const Params& p, std::size_t n,
                              const PlacementGrid& grid = {});

}  // namespace vdyn
