// The equations of motion: forces on the body and the state derivative xdot = f(x, u).
//
// One evaluation reads as its stages (docs/model.md gives every equation):
//   1. sense terrain   - a vertical line trace per wheel from A along -Z_B (the paper's A-B)
//   2. suspension      - spring length lS, deformation lT, spring force Fp (never pulling)
//   3. tire forces     - drive Fh, brake Fb, side Fy, all bounded by mu * Fp
//   4. body forces     - gravity, aerodynamic drag Da, wall contacts from the horizontal traces
//   5. derivatives     - Newton for T, Euler for the body rates, quaternion kinematics
#pragma once

#include <array>

#include "vdyn/physics/controls.h"
#include "vdyn/physics/params.h"
#include "vdyn/physics/state.h"
#include "vdyn/physics/terrain.h"

namespace vdyn {

// Per-wheel quantities at one state (what the CSV, the state topic and the viewer show).
struct WheelOutputs {
  bool contact = false;
  double Fp = 0;          // spring force = normal force, N (>= 0)
  double Fh = 0;          // drive force applied, N (signed along the wheel heading)
  double Fb = 0;          // brake force applied, N (>= 0, opposing the wheel's motion)
  double Fy = 0;          // side force, N (along the wheel's lateral axis, positive to the left)
  double Frr = 0;         // rolling resistance, N (>= 0)
  double lS = 0;          // instant spring length, m
  double lT = 0;          // spring deformation lT = free length - lS, m
  double lS_rate = 0;     // d(lS)/dt, m/s
  double gamma = 0;       // wheel steering angle, rad
  double slip_angle = 0;  // rad
  double v_long = 0;      // contact point velocity along the wheel heading, m/s
  double v_lat = 0;       // ... along the wheel's lateral axis, m/s
  Eigen::Vector3d p_A_W = Eigen::Vector3d::Zero();  // mount point A
  Eigen::Vector3d p_B_W = Eigen::Vector3d::Zero();  // contact point B (or wheel bottom in the air)
  Eigen::Vector3d n_W = Eigen::Vector3d::UnitZ();   // terrain normal at B
  Eigen::Vector3d F_W = Eigen::Vector3d::Zero();    // total wheel force on the body at B
  // Full model (zero for the paper's): the wheel's spin and the tire's own forces.
  double omega = 0;         // spin rate, rad/s
  double slip_ratio = 0;    // (omega R - v_long) / max(|v_long|, 1 m/s)
  double slip_ratio_t = 0;  // transient slip ratio kappa' = u / sigma_long
  double slip_angle_t = 0;  // transient slip angle atan(v / sigma_lat), rad
  double Fx = 0;            // tire force along the wheel heading, N
  double Mz = 0;            // aligning moment about the contact normal, N*m (positive: turns left)
  double drive_torque = 0;  // N*m
  double brake_torque = 0;  // N*m (>= 0, applied)
  bool kerb = false;        // an edge found by the C-D traces carries part of the load
  // The tyre law's inputs and its other outputs (full model; what a reader needs to evaluate the
  // law again at this point): the slips it read (the transient slips plus the low-speed damping),
  // the inclination and the inflation pressure (a Magic Formula tyre's; 0 for the brush law,
  // which reads neither), the overturning moment (Magic Formula) and the rolling resistance
  // moment applied.
  double kappa_law = 0;  // longitudinal slip the law read
  double alpha_law = 0;  // slip angle the law read, rad
  double camber = 0;     // inclination to the ground, rad (ISO-W: > 0 leans the top right)
  double pressure = 0;   // inflation pressure, Pa
  double Mx = 0;         // overturning moment, N*m (about the wheel heading)
  double My = 0;         // rolling resistance moment, N*m (< 0 against forward rolling)
};

// A wall found by a horizontal trace at the start of a step; contact at each stage is evaluated
// against this plane (the trace runs once per step, the terrain under the wheels every stage).
struct WallPlane {
  bool active = false;
  Eigen::Vector3d p_W = Eigen::Vector3d::Zero();  // hit point D
  Eigen::Vector3d n_W = Eigen::Vector3d::UnitX(); // unit normal, facing the body
};
using WallPlanes = std::array<WallPlane, Params::kNumProbes>;

// A wall contact's normal force never exceeds wall_stiffness times this depth, m.
inline constexpr double kWallPenetrationCap = 0.2;

struct Derived {
  std::array<WheelOutputs, kNumWheels> wheel{};
  bool any_contact = false;
  double Da = 0;                                        // drag, N (positive opposes forward motion)
  double steering_torque = 0;  // at the hand wheel, N*m, positive turns it left (force feedback)
  Eigen::Vector3d F_W = Eigen::Vector3d::Zero();        // total force on the body incl. gravity
  Eigen::Vector3d M_B = Eigen::Vector3d::Zero();        // total moment about T, body axes
  Eigen::Vector3d a_WT_W = Eigen::Vector3d::Zero();     // acceleration of T, world axes
  Eigen::Vector3d dw_B = Eigen::Vector3d::Zero();       // angular acceleration, body axes
  Eigen::Vector3d w_eff_B = Eigen::Vector3d::Zero();    // body rates used (paper yaw mode)
  Eigen::Vector3d F_wall_W = Eigen::Vector3d::Zero();   // sum of wall contact forces
  double wall_penetration_max = 0;                      // m
  int wall_contacts = 0;

  // Full model: the steering system (torques at the hand wheel, positive turning it left; their
  // sum is steering_torque) and the drivetrain.
  struct Steering {
    double angle = 0, rate = 0;  // hand wheel, rad and rad/s
    double aligning = 0, trail = 0, friction = 0, damping = 0, end_stop = 0;  // N*m
    double driver = 0;           // the hands' torque that makes the column follow, N*m
  } steering;
  struct Drivetrain {
    double engine_speed = 0;   // rad/s
    double engine_torque = 0;  // N*m
    double throttle = 0;       // at the engine, [0, 1]
    double clutch_torque = 0;  // N*m
    double clutch_slip = 0;    // rad/s, engine minus gearbox input
  } drivetrain;
};

// The body's pose and motion at one state, computed once per evaluation and read by every stage.
struct BodyKinematics {
  Eigen::Matrix3d R_WB;
  Eigen::Vector3d p_WT_W;
  Eigen::Vector3d v_WT_W;
  Eigen::Vector3d down_W;  // -Z_B, the direction of the vertical traces
  Eigen::Vector3d w_WB_B;  // body rates in effect (eq. 6 replaces the yaw rate in paper yaw mode)
  Eigen::Vector3d w_WB_W;
  bool paper_yaw = false;  // the yaw rate is imposed by eq. 6 (paper yaw mode, a wheel touching)
};

// The forces on the body, summed in a fixed order (wheels LF..RR, then drag, then walls), so the
// result is the same bit for bit however the stages are arranged.
struct BodyLoads {
  Eigen::Vector3d F_W;  // total force, world axes (gravity included)
  Eigen::Vector3d M_W;  // moment about T of the wheel and wall forces, world axes
  Eigen::Vector3d M_B;  // moment about T of the drag, body axes
};

// Casts the horizontal traces at state x; a hit on a steep surface (|n_z| < 0.7) becomes a wall.
// Returns whether the traces were cast (false on open ground, where the steep-surface grid says
// no wall can be within reach).
bool FindWalls(const Params& p, const Terrain& terrain, const StateVector& x, WallPlanes& walls);

// xdot = f(x) with the controls held, filling `out` with every intermediate quantity. With
// report_all false, quantities that only outputs use (the slip angle) are skipped. It runs the
// stages below in order.
void EvaluateDerivative(const Params& p, const Terrain& terrain, const AppliedControl& u,
                        const WallPlanes& walls, const StateVector& x, StateVector& xdot,
                        Derived& out, bool report_all = true);

// --- The stages of one evaluation (docs/model.md, sections 1-5) -------------------------------
// 1. Sense terrain: the body's kinematics, and the vertical trace from each mount point A
//    (contact, AB, the terrain's normal at B). Decides the paper yaw mode's imposed yaw rate.
void SenseTerrain(const Params& p, const Terrain& terrain, const AppliedControl& u,
                  const StateVector& x, BodyKinematics& k, std::array<TraceHit, kNumWheels>& hits,
                  Derived& out);
// 2. Suspension of one wheel: spring length, deformation and rate, spring force Fp (>= 0).
void Suspension(const WheelParams& wp, const BodyKinematics& k, const TraceHit& hit,
                WheelOutputs& o);
// 3. Tire forces of one wheel in the terrain's tangent plane: drive, brake, rolling resistance and
//    side force inside the friction circle; their sum F_W at B.
void TireForces(const Params& p, const AppliedControl& u, int w, const BodyKinematics& k,
                bool report_all, WheelOutputs& o);
// 4. Body forces: gravity, the wheels' forces at B, drag at ha, wall contacts at the probes.
BodyLoads BodyForces(const Params& p, const WallPlanes& walls, const BodyKinematics& k,
                     Derived& out);
// 5. Derivatives: Newton for T, Euler for the body rates, quaternion kinematics.
void Derivatives(const Params& p, const BodyKinematics& k, const BodyLoads& loads,
                 const StateVector& x, StateVector& xdot, Derived& out);

// The tire's lateral force (N) at tan(slip angle) for normal load Fz: linear in the small-slip
// range with slope -C_alpha, never above mu * Fz in magnitude.
double TireLateralForce(TireLaw law, double tan_alpha, double cornering_stiffness, double mu,
                        double Fz);

}  // namespace vdyn
