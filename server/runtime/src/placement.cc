#include "vdyn/runtime/placement.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>

#include "vdyn/physics/simulator.h"

namespace vdyn {
namespace {

struct Cell {
  int row = 0;     // along the spawn's heading (negative: behind)
  int column = 0;  // to its left (negative: right)
  double distance_m = 0;
};

// Empty when a vehicle with parameters `p` rests at `pose` inside nothing; else why not.
std::string Obstruction(const World& world, const Params& p, const Pose2& pose) {
  double misfit = 0.0;
  const State s = RestingState(p, world.terrain, pose, 0.0, &misfit);  // WorldError: no ground
  return SpawnObstruction(p, world.terrain, s, misfit);
}

}  // namespace

std::vector<Pose2> StartPoses(const World& world, const Params& p, std::size_t n,
                              const PlacementGrid& grid) {
  std::vector<Pose2> poses;
  if (n == 0) return poses;
  const Pose2 spawn = world.spawn;
  // The first vehicle where the world (or --spawn) says: if it cannot start there, say why.
  if (std::string why = Obstruction(world, p, spawn); !why.empty()) throw WorldError(why);
  poses.push_back(spawn);
  if (n == 1) return poses;

  const int rows = static_cast<int>(std::floor(grid.reach_m / grid.along_m));
  const int columns = static_cast<int>(std::floor(grid.reach_m / grid.across_m));
  std::vector<Cell> cells;
  for (int r = -rows; r <= rows; ++r) {
    for (int c = -columns; c <= columns; ++c) {
      const double d = std::hypot(r * grid.along_m, c * grid.across_m);
      if ((r != 0 || c != 0) && d <= grid.reach_m) cells.push_back({r, c, d});
    }
  }
  // Behind or beside the spawn first, then nearest first; a tie goes left, then behind.
  std::sort(cells.begin(), cells.end(), [](const Cell& a, const Cell& b) {
    if ((a.row > 0) != (b.row > 0)) return a.row <= 0;
    if (a.distance_m != b.distance_m) return a.distance_m < b.distance_m;
    if (a.column != b.column) return a.column > b.column;
    return a.row < b.row;
  });
  const double c = std::cos(spawn.yaw), s = std::sin(spawn.yaw);
  for (const Cell& cell : cells) {
    if (poses.size() == n) break;
    const double ahead = cell.row * grid.along_m, left = cell.column * grid.across_m;
    const Pose2 pose{spawn.x + c * ahead - s * left, spawn.y + s * ahead + c * left, spawn.yaw};
    try {
      if (Obstruction(world, p, pose).empty()) poses.push_back(pose);
    } catch (const WorldError&) {
      // No ground below: not a place to start.
    }
  }
  if (poses.size() < n) {
    char grid_text[160];
    std::snprintf(grid_text, sizeof grid_text,
                  "within %g m of its spawn (side by side %g m apart, nose to tail %g m)",
                  grid.reach_m, grid.across_m, grid.along_m);
    throw WorldError("only " + std::to_string(poses.size()) + " of the " + std::to_string(n) +
                     " vehicles fit on the free ground of world '" + world.name + "' " + grid_text +
                     ": start at most " + std::to_string(poses.size()) +
                     " (--vehicle-ids), or choose another --spawn or --world");
  }
  return poses;
}

}  // namespace vdyn
