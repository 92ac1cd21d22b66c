// Worlds: the terrain plus what a user and a viewer need to know about it.
#pragma once

#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "vdyn/physics/terrain.h"

namespace vdyn {

struct Pose2 {
  double x = 0, y = 0;  // m, world
  double yaw = 0;       // rad, heading from +X_W towards +Y_W
};

// A named point of a built-in world (for tests, maneuvers and viewers).
struct Landmark {
  std::string name;
  Eigen::Vector3d p_W;
};

struct World {
  std::string name;
  Terrain terrain;
  Pose2 spawn;
  // Direction of north as a heading in the world XY plane, rad (built-in worlds: +Y_W is north).
  double north_yaw = 1.5707963267948966;
  std::vector<Landmark> landmarks;

  // Throws std::out_of_range naming the landmark when absent.
  const Eigen::Vector3d& LandmarkAt(const std::string& landmark) const;
};

class WorldError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A world of one mesh (named after it), committed, with the given spawn pose.
std::unique_ptr<World> WorldFromMesh(TriangleMesh mesh, const Pose2& spawn);

// Built-in worlds generated in code: "facility" (the paper's test facility) and "flat".
std::unique_ptr<World> BuildBuiltinWorld(const std::string& name);
std::vector<std::string> BuiltinWorldNames();

}  // namespace vdyn
