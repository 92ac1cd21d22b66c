// Ray sets for the ray-cast benchmarks: where a car's wheels would cast their vertical rays.
#pragma once

#include <array>
#include <vector>

#include <Eigen/Core>

#include "cars.h"

namespace vdyn::bench {

// Per sample, the four wheel-ray origins (LF, RF, LR, RR) of a car at one pose, each 0.7 m above
// the ground below it (about where vdyn's trace starts: a wheel radius above the mount point),
// cast straight down with range t_max = 1 m (lift + free length + radius).
struct RaySet {
  std::vector<std::array<Eigen::Vector3d, 4>> origins;
  double t_max = 1.0;
};

// A car moving at 50 km/h sampled at 1 kHz: consecutive samples 1.4 cm apart along the course
// (facility: the test road; the generated terrain: a circle of radius 150 m).
RaySet MovingRays(const Course& course);
// 65536 car poses drawn uniformly over the course's area with random headings (integer hash).
RaySet RandomRays(const Course& course);

}  // namespace vdyn::bench
