// The drives the benchmarks time, and the two cars that drive them: vdyn's Simulator and, as the
// peer, a Bullet btRaycastVehicle built from the same parameters on the same triangles.
//
// Both cars get the same driver (Course::Steer and a set speed), start from the same resting state
// (vdyn::RestingState) and are put back to a spawn pose when they would leave the course. A
// benchmark times Step(); Respawn() is setup and stays out of the timed region.
#pragma once

#include <memory>
#include <string>

#include <Eigen/Core>

#include "vdyn/physics/params.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/physics/world.h"

namespace vdyn::bench {

struct Course {
  std::string name;  // "facility" or "terrain_1m"
  std::shared_ptr<const World> world;
  double speed = 0;  // set speed, m/s

  // The k-th spawn pose (k = 0, 1, ...).
  Pose2 SpawnPose(int k) const;
  // The driver's steering at time t since the spawn, rad, positive to the left.
  double Steer(double t, const Pose2& pose) const;
  // Whether the car is about to leave the course (end of the road, edge of the mesh).
  bool Leaving(const Pose2& pose) const;
};

// facility: the test road west to east at 50 km/h holding the lane, over the speed bumps, the
// washboard and the one-sided bump, back to the start before jump ramp A.
Course FacilityCourse();
// The generated 1M-triangle terrain at 15 m/s, weaving gently, from the centre outwards with the
// heading turned by the golden angle at each spawn.
Course TerrainCourse();

ValidParams BenchParams();       // vdyn's default vehicle (the full model, the default)
ValidParams PaperBenchParams();  // the same vehicle with the paper's model
// The same vehicle on the synthetic Magic Formula tyre (tires/vdyn_synthetic_205_55R16_mf61.tir).
ValidParams MagicFormulaBenchParams();

class VdynCar {
 public:
  VdynCar(const Course& course, const ValidParams& params);
  // One step: the driver's input, then Simulator::Step. False when the step was not finite.
  bool Step();
  bool NeedsRespawn() const { return course_.Leaving(pose_); }
  void Respawn();
  const Pose2& pose() const { return pose_; }
  const Simulator& sim() const { return sim_; }

 private:
  Course course_;
  Simulator sim_;
  Pose2 pose_;
  double t_spawn_ = 0;
  int spawns_ = 0;
};

class BulletCar {
 public:
  // chassis_box: the chassis is a box that collides with the terrain (Bullet's usual setup, and
  // the counterpart of vdyn's wall contacts); without it only the wheel rays touch the terrain.
  BulletCar(const Course& course, const Params& params, bool chassis_box = true);
  ~BulletCar();
  BulletCar(const BulletCar&) = delete;
  BulletCar& operator=(const BulletCar&) = delete;

  bool Step();
  bool NeedsRespawn() const { return course_.Leaving(pose_); }
  void Respawn();
  const Pose2& pose() const { return pose_; }
  // A ray cast the way the vehicle casts its wheel rays (btDefaultVehicleRaycaster, this world).
  // Returns whether it hit; *fraction is the hit's fraction of from -> to.
  bool CastRay(const Eigen::Vector3d& from, const Eigen::Vector3d& to, double* fraction);
  double speed() const;  // m/s along the chassis' forward axis

 private:
  struct Impl;
  Course course_;
  Params params_;
  std::unique_ptr<Impl> impl_;
  Pose2 pose_;
  double t_ = 0;  // s since the spawn
  int spawns_ = 0;
};

}  // namespace vdyn::bench
