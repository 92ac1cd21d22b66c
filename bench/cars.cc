#include "cars.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>

#include <BulletCollision/CollisionShapes/btBvhTriangleMeshShape.h>
#include <BulletCollision/CollisionShapes/btTriangleMesh.h>
#include <BulletDynamics/Vehicle/btRaycastVehicle.h>
#include <btBulletDynamicsCommon.h>

#include "terrain_gen.h"
#include "vdyn/bridge/params.h"
#include "vdyn/io/tire_file.h"

namespace vdyn::bench {

// --- courses ---------------------------------------------------------------------------------

namespace {
constexpr double kRoadY = -150.0;  // facility's test road centre line, m
// Back to the start before jump ramp A (x = 40 m): Bullet's car, without a bump stop, lands nose
// first from the jump and crashes, after which the two cars would no longer drive the same course.
constexpr double kRoadEndX = 35.0;
constexpr double kEdgeMargin = 15.0;                // m kept from the generated terrain's edge
constexpr double kGoldenAngle = 2.399963229728653;  // rad
}  // namespace

Course FacilityCourse() {
  return {"facility", FacilityWorld(), 50.0 / 3.6};
}
Course TerrainCourse() {
  return {"terrain_1m", GeneratedTerrainWorld(), 15.0};
}

Pose2 Course::SpawnPose(int k) const {
  if (name == "facility") return world->spawn;
  return {0.0, 0.0, std::remainder(k * kGoldenAngle, 2.0 * std::numbers::pi)};
}

double Course::Steer(double t, const Pose2& pose) const {
  if (name == "facility") {
    // Lane keeping on the road's centre line: critically damped at ~0.5 rad/s for 14 m/s
    // (y'' + v k_yaw / L y' + v^2 k_y / L y = 0 for the kinematic bicycle).
    const double steer =
        -0.0035 * (pose.y - kRoadY) - 0.2 * std::remainder(pose.yaw, 2 * std::numbers::pi);
    return std::clamp(steer, -0.05, 0.05);
  }
  // A gentle weave: +-0.02 rad over 8 s (about 1.7 m/s^2 of lateral acceleration at 15 m/s).
  return 0.02 * std::sin(2.0 * std::numbers::pi * t / 8.0);
}

bool Course::Leaving(const Pose2& pose) const {
  if (name == "facility") return pose.x > kRoadEndX || std::abs(pose.y - kRoadY) > 3.5;
  const double limit = TerrainSpec{}.half_size() - kEdgeMargin;
  return std::abs(pose.x) > limit || std::abs(pose.y) > limit;
}

ValidParams BenchParams() {
  return ParamsFromProto(DefaultVehicleParams());
}

ValidParams MagicFormulaBenchParams() {
  pb::VehicleParams p = DefaultVehicleParams();
  const pb::MagicFormulaTire tire = ReadTireFile(std::filesystem::path(VDYN_SOURCE_DIR) / "tires" /
                                                 "vdyn_synthetic_205_55R16_mf61.tir");
  for (pb::WheelParams* w : {p.mutable_lf(), p.mutable_rf(), p.mutable_lr(), p.mutable_rr()}) {
    *w->mutable_magic_formula() = tire;
  }
  return ParamsFromProto(p);
}

ValidParams PaperBenchParams() {
  pb::VehicleParams p = DefaultVehicleParams();
  p.set_model(pb::VEHICLE_MODEL_PAPER);
  return ParamsFromProto(p);
}

// --- vdyn --------------------------------------------------------------------------------------

namespace {
Pose2 PoseOf(const State& s) {
  const Eigen::Quaterniond q = Orientation(s.x);
  const double yaw = std::atan2(2.0 * (q.w() * q.z() + q.x() * q.y()),
                                1.0 - 2.0 * (q.y() * q.y() + q.z() * q.z()));
  return {s.x[sx::kP], s.x[sx::kP + 1], yaw};
}
}  // namespace

VdynCar::VdynCar(const Course& course, const ValidParams& params)
    : course_(course), sim_(course.world, params) {
  Respawn();
}

void VdynCar::Respawn() {
  sim_.Spawn(course_.SpawnPose(spawns_++), course_.speed);
  pose_ = PoseOf(sim_.state());
  t_spawn_ = sim_.time();
}

bool VdynCar::Step() {
  DriverInput in;
  in.steer = course_.Steer(sim_.time() - t_spawn_, pose_);
  in.cruise_on = true;
  in.cruise_speed = course_.speed;
  sim_.SetInput(in);
  const bool ok = sim_.Step() == StepStatus::kOk;
  pose_ = PoseOf(sim_.state());
  return ok;
}

// --- Bullet ------------------------------------------------------------------------------------
//
// Frames. vdyn's body frame is X forward, Y left, Z up. btRaycastVehicle builds each wheel's basis
// as (right, forward, up) in columns 0, 1, 2 and reads the axle from column m_indexRightAxis, so it
// only works with right = 0; we therefore give the chassis Bullet's own layout, X right, Y forward,
// Z up (setCoordinateSystem(0, 2, 1)): R_W_chassis = R_WB * Rz(-90 deg), p_bt = (-y, x, z).
// The wheel's forward direction is contact normal x axle, so the axle is +X (right) for +Y forward.
//
// Suspension. btRaycastVehicle::updateSuspension computes, per wheel,
//   F = m_chassis * (stiffness * (rest_length - length) / cos - damping * v_rel)
// (cos: contact normal against the suspension axis, v_rel: compression speed), i.e. stiffness and
// damping are per unit chassis mass. vdyn's F = k (free_length - lS) - c dlS/dt maps exactly with
//   stiffness = k / m,  damping (compression and relaxation) = c / m,  rest length = free length.
// (Bullet's docs speak of damping as 2 * zeta * sqrt(stiffness): that is the same number c / m
// when zeta is taken against the whole chassis mass, not the wheel's share.) Not mapped, because
// Bullet has no equivalent: the bump stop, the tire's cornering stiffness (Bullet's side friction
// is an impulse that cancels the lateral velocity, bounded by frictionSlip * Fz), drag and rolling
// resistance. m_rollInfluence = 1 keeps side forces at the contact point as in vdyn (Bullet's
// default 0.1 moves them up towards the centre of mass to fake roll stability).

namespace {

// Bullet keeps pointers to the mesh: one per course for the whole process (built once, the BVH of
// the 1M triangles included), shared by every BulletCar on that course.
struct BulletTerrain {
  btTriangleMesh mesh;  // 32-bit indices, 4-component vertices: Bullet's defaults
  std::unique_ptr<btBvhTriangleMeshShape> shape;
};

btBvhTriangleMeshShape& TerrainShape(const Course& course) {
  static std::map<std::string, std::unique_ptr<BulletTerrain>> cache;
  std::unique_ptr<BulletTerrain>& t = cache[course.name];
  if (!t) {
    t = std::make_unique<BulletTerrain>();
    // Every mesh of the world (ground, road, bumps, ramps, barrier, ...) in one btTriangleMesh.
    std::size_t nv = 0, nt = 0;
    for (const TriangleMesh& m : course.world->terrain.meshes()) {
      nv += m.vertices_W.size();
      nt += m.triangles.size();
    }
    t->mesh.preallocateVertices(static_cast<int>(nv));
    t->mesh.preallocateIndices(static_cast<int>(3 * nt));
    for (const TriangleMesh& m : course.world->terrain.meshes()) {
      int base = -1;
      for (const Eigen::Vector3d& v : m.vertices_W) {
        const int i = t->mesh.findOrAddVertex(
            btVector3(static_cast<btScalar>(v.x()), static_cast<btScalar>(v.y()),
                      static_cast<btScalar>(v.z())),
            false);
        if (base < 0) base = i;
      }
      for (const auto& tri : m.triangles) {
        t->mesh.addTriangleIndices(base + static_cast<int>(tri[0]), base + static_cast<int>(tri[1]),
                                   base + static_cast<int>(tri[2]));
      }
    }
    t->shape = std::make_unique<btBvhTriangleMeshShape>(&t->mesh, true);  // quantized BVH
  }
  return *t->shape;
}

btVector3 Bt(const Eigen::Vector3d& v) {
  return {static_cast<btScalar>(v.x()), static_cast<btScalar>(v.y()), static_cast<btScalar>(v.z())};
}

// The chassis never meets its own wheel rays: rays (btDefaultVehicleRaycaster) are in the default
// group, the chassis only collides with static geometry.
constexpr int kChassisGroup = 64;

}  // namespace

struct BulletCar::Impl {
  btDefaultCollisionConfiguration config;
  btCollisionDispatcher dispatcher{&config};
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btDiscreteDynamicsWorld world{&dispatcher, &broadphase, &solver, &config};
  std::unique_ptr<btRigidBody> ground;
  std::unique_ptr<btBoxShape> chassis_shape;
  std::unique_ptr<btRigidBody> chassis;
  btDefaultVehicleRaycaster raycaster{&world};
  std::unique_ptr<btRaycastVehicle> vehicle;

  ~Impl() {
    world.removeAction(vehicle.get());
    world.removeRigidBody(chassis.get());
    world.removeRigidBody(ground.get());
  }
};

BulletCar::BulletCar(const Course& course, const Params& params, bool chassis_box)
    : course_(course), params_(params), impl_(std::make_unique<Impl>()) {
  Impl& b = *impl_;
  b.world.setGravity(btVector3(0, 0, static_cast<btScalar>(-params.gravity)));
  b.ground = std::make_unique<btRigidBody>(
      btRigidBody::btRigidBodyConstructionInfo(0, nullptr, &TerrainShape(course)));
  b.world.addRigidBody(b.ground.get(), btBroadphaseProxy::StaticFilter,
                       btBroadphaseProxy::AllFilter ^ btBroadphaseProxy::StaticFilter);

  // Chassis: the body box the vdyn model probes for walls (front + rear long, 0.6 m tall,
  // centred on T), vdyn's mass and principal inertia in the chassis' axes (right, forward, up).
  const Params& p = params;
  b.chassis_shape = std::make_unique<btBoxShape>(
      btVector3(static_cast<btScalar>(p.body_half_width),
                static_cast<btScalar>(0.5 * (p.body_front + p.body_rear)), btScalar(0.3)));
  const btVector3 inertia(static_cast<btScalar>(p.inertia_B.y()),
                          static_cast<btScalar>(p.inertia_B.x()),
                          static_cast<btScalar>(p.inertia_B.z()));
  b.chassis = std::make_unique<btRigidBody>(btRigidBody::btRigidBodyConstructionInfo(
      static_cast<btScalar>(p.mass), nullptr, b.chassis_shape.get(), inertia));
  b.chassis->setActivationState(DISABLE_DEACTIVATION);
  b.world.addRigidBody(b.chassis.get(), kChassisGroup,
                       chassis_box ? btBroadphaseProxy::StaticFilter : 0);

  btRaycastVehicle::btVehicleTuning tuning;
  b.vehicle = std::make_unique<btRaycastVehicle>(tuning, b.chassis.get(), &b.raycaster);
  b.vehicle->setCoordinateSystem(0, 2, 1);
  b.world.addAction(b.vehicle.get());
  for (int w = 0; w < kNumWheels; ++w) {
    const WheelParams& wp = p.wheel[w];
    const Eigen::Vector3d& a = p.p_TA_B[w];  // mount point A
    btWheelInfo& wi = b.vehicle->addWheel(
        btVector3(static_cast<btScalar>(-a.y()), static_cast<btScalar>(a.x()),
                  static_cast<btScalar>(a.z())),
        btVector3(0, 0, -1), btVector3(1, 0, 0), static_cast<btScalar>(wp.free_length),
        static_cast<btScalar>(wp.radius), tuning, IsFront(w));
    wi.m_suspensionStiffness = static_cast<btScalar>(wp.spring_stiffness / p.mass);
    wi.m_wheelsDampingCompression = static_cast<btScalar>(wp.damper_coefficient / p.mass);
    wi.m_wheelsDampingRelaxation = wi.m_wheelsDampingCompression;
    wi.m_maxSuspensionTravelCm = static_cast<btScalar>(100.0 * wp.free_length);
    wi.m_maxSuspensionForce = btScalar(1e6);  // no cap (Bullet's default is 6 kN)
    wi.m_frictionSlip = static_cast<btScalar>(p.mu);
    wi.m_rollInfluence = 1;
  }
  Respawn();
}

BulletCar::~BulletCar() = default;

void BulletCar::Respawn() {
  Impl& b = *impl_;
  // vdyn's resting state on the same terrain, so both cars start alike.
  const State s =
      RestingState(params_, course_.world->terrain, course_.SpawnPose(spawns_++), course_.speed);
  const Eigen::Quaterniond q =
      Orientation(s.x) *
      Eigen::Quaterniond(Eigen::AngleAxisd(-0.5 * std::numbers::pi, Eigen::Vector3d::UnitZ()));
  btTransform tr;
  tr.setOrigin(Bt(Position(s.x)));
  tr.setRotation(btQuaternion(static_cast<btScalar>(q.x()), static_cast<btScalar>(q.y()),
                              static_cast<btScalar>(q.z()), static_cast<btScalar>(q.w())));
  b.chassis->setCenterOfMassTransform(tr);
  b.chassis->setLinearVelocity(Bt(Velocity(s.x)));
  b.chassis->setAngularVelocity(btVector3(0, 0, 0));
  b.chassis->clearForces();
  // Contacts from the old place must not push the car at the new one.
  b.world.getBroadphase()->getOverlappingPairCache()->cleanProxyFromPairs(
      b.chassis->getBroadphaseHandle(), b.world.getDispatcher());
  b.vehicle->resetSuspension();
  for (int w = 0; w < kNumWheels; ++w) b.vehicle->updateWheelTransform(w, false);
  pose_ = course_.SpawnPose(spawns_ - 1);
  t_ = 0;
}

double BulletCar::speed() const {
  const btRigidBody& c = *impl_->chassis;
  return static_cast<double>(
      c.getCenterOfMassTransform().getBasis().getColumn(1).dot(c.getLinearVelocity()));
}

bool BulletCar::Step() {
  Impl& b = *impl_;
  const double h = 1e-3;
  // The same driver: steering from the course; speed held by a proportional control with vdyn's
  // cruise gain on its drive force, on the driven (front) wheels. Bullet has no drag or rolling
  // resistance, so no integral term is needed to hold the speed.
  const auto steer = static_cast<btScalar>(
      std::clamp(course_.Steer(t_, pose_), -params_.steering_lock, params_.steering_lock));
  const double u = std::clamp(params_.cruise_kp * (course_.speed - speed()), -1.0, 1.0);
  const auto drive = static_cast<btScalar>(0.5 * u * params_.drive_force_max);
  for (int w : {kLF, kRF}) {
    b.vehicle->setSteeringValue(steer, w);
    b.vehicle->applyEngineForce(drive, w);
  }
  // One internal step of exactly h: maxSubSteps = 0 steps by the given time step, no
  // accumulator and no interpolation.
  b.world.stepSimulation(static_cast<btScalar>(h), 0);
  t_ += h;
  const btTransform& tr = b.chassis->getCenterOfMassTransform();
  const btVector3 f = tr.getBasis().getColumn(1);
  pose_ = {static_cast<double>(tr.getOrigin().x()), static_cast<double>(tr.getOrigin().y()),
           std::atan2(static_cast<double>(f.y()), static_cast<double>(f.x()))};
  return std::isfinite(pose_.x) && std::isfinite(pose_.y);
}

bool BulletCar::CastRay(const Eigen::Vector3d& from, const Eigen::Vector3d& to, double* fraction) {
  btVehicleRaycaster::btVehicleRaycasterResult r;
  const bool hit = impl_->raycaster.castRay(Bt(from), Bt(to), r) != nullptr;
  *fraction = hit ? static_cast<double>(r.m_distFraction) : 1.0;
  return hit;
}

}  // namespace vdyn::bench
