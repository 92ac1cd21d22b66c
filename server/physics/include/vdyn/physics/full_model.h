// The full model (VehicleModel::kFull): the paper's rigid body, terrain traces and walls, plus
// a brush tire with combined slip, aligning moment, relaxation and radial compliance; wheel spin;
// an engine, clutch, gearbox and differentials; a steering system with Ackermann geometry and a
// steering column; kerbs found by wheel-level horizontal traces; suspension travel limited by
// stops. docs/model.md ("The full model") gives every equation.
//
// One evaluation of the derivative reads as its stages:
//   1. sense terrain     - body kinematics; the vertical trace per wheel (a steep face is
//                          traced past, never taken for ground)
//   2. steering geometry - the column's angle to the road-wheel angles (Ackermann)
//   3. suspension        - the tire's normal load from the ground and from kerb edges, the spring
//                          length's rate (tire in series with spring and damper, massless wheel)
//   4. tire forces       - transient slips from the contact patch's deflections, the brush law,
//                          the deflections' rates
//   5. drivetrain        - engine, clutch, differentials, brakes: the wheels' spin rates
//   6. steering column   - the tire moments about the steering axes, friction, damping, stops
//   7. body forces and derivatives, as the paper's model
#pragma once

#include <algorithm>
#include <array>
#include <cmath>

#include "vdyn/physics/controls.h"
#include "vdyn/physics/params.h"
#include "vdyn/physics/state.h"
#include "vdyn/physics/terrain.h"
#include "vdyn/physics/vehicle_model.h"

namespace vdyn {

// An edge of a steep face (a kerb) ahead of or behind a wheel, found by the wheel-level
// horizontal traces (the paper's C-D) at the start of a step and held for the step.
struct WheelEdge {
  bool active = false;
  Eigen::Vector3d p_E_W = Eigen::Vector3d::Zero();  // the top edge of the face, world
};
struct WheelEdges {
  std::array<std::array<WheelEdge, 2>, kNumWheels> wheel{};  // [w][0] ahead, [w][1] behind
};

// Casts the wheel-level horizontal traces at state x (only where the steep-surface grid says a
// steep face may be near): from just above each wheel's ground point along the ground, ahead and
// behind; a steep face no higher than 0.6 wheel radii becomes an edge. Returns whether the
// traces were cast.
bool FindWheelEdges(const Params& p, const Terrain& terrain, const StateVector& x,
                    WheelEdges& edges);

// xdot = f(x) for the full model, with the controls, walls and edges held. Fills `out` like the
// paper's EvaluateDerivative; with report_all false, quantities only outputs use are skipped.
void EvaluateDerivativeFull(const Params& p, const Terrain& terrain, const AppliedControl& u,
                            const WallPlanes& walls, const WheelEdges& edges, const StateVector& x,
                            StateVector& xdot, Derived& out, bool report_all = true);

// The controls stage of the full model (called by ComputeControls): steering command, pedals,
// speed control, the gearbox (automatic, or the driver's gear), shift timing, ABS and traction
// control, updating state.cruise_integral and state.discrete.
AppliedControl ComputeControlsFull(const Params& p, const DriverInput& in, double h, State& state);

// --- The tire law: the brush model with adhesion limit mu0 and sliding friction mu_slide ---------
// (parabolic pressure; mu0 = Params::full.mu_static, chosen so that the peak is mu). With z the
// normalised slip (1 at the onset of full sliding):
//   F / Fz = 3 mu0 z (1 - z)^2 + mu_slide z^2 (3 - 2 z)        z < 1;   mu_slide   z >= 1
// BrushForceRatio returns F / Phi with Phi = 3 mu0 Fz z, the linear force (finite at z = 0).
// (Inline: the derivative calls these at every stage.)
inline double BrushForceRatio(double z, double mu0, double mu_slide) {
  if (z >= 1.0) return mu_slide / (3.0 * mu0 * z);
  const double q = 1.0 - z;
  return q * q + mu_slide / (3.0 * mu0) * z * (3.0 - 2.0 * z);
}

// Pneumatic trail over the contact half length a:
//   t / a = (1 - z)^2 (mu0 (1 - 4 z) + 3 mu_slide z) / (3 mu0 (1 - z)^2 + mu_slide z (3 - 2 z))
// for z < 1 (a / 3 at z = 0), 0 for z >= 1.
inline double BrushTrailRatio(double z, double mu0, double mu_slide) {
  if (z >= 1.0) return 0.0;
  const double q = 1.0 - z;
  return q * q * (mu0 * (1.0 - 4.0 * z) + 3.0 * mu_slide * z) /
         (3.0 * mu0 * q * q + mu_slide * z * (3.0 - 2.0 * z));
}

// Cornering stiffness at load Fz: C_alpha(Fz) = C_alpha sin(2 atan(Fz / (p Fz0))) / sin(2 atan(1/p)),
// with sin(2 atan x) = 2 x / (1 + x^2).
inline double CorneringStiffnessAt(const Params& p, int w, double Fz) {
  const WheelParams& wp = p.wheel[w];
  const double x = Fz / (p.tire_load_sensitivity * wp.nominal_load);
  return wp.cornering_stiffness * p.full.load_sensitivity_norm[w] * 2.0 * x / (1.0 + x * x);
}

// The road-wheel angles of the front wheels for a hand-wheel angle (Ackermann), and how fast
// each turns with the rack's angle delta = hand-wheel angle / steering ratio.
struct FrontWheelAngles {
  std::array<double, 2> cos_gamma{1.0, 1.0}, sin_gamma{0.0, 0.0};  // LF, RF
  std::array<double, 2> dgamma_ddelta{1.0, 1.0};
};
inline FrontWheelAngles SteeringGeometry(const Params& p, double hand_wheel_angle) {
  FrontWheelAngles g;
  // The rack's angle delta (a virtual centre wheel); Ackermann: cot(gamma_L) = cot(delta) - k/L,
  // cot(gamma_R) = cot(delta) + k/L with k = ackermann * track / 2.
  const double delta = std::clamp(hand_wheel_angle / p.steering_ratio, -1.55, 1.55);
  const double t = std::tan(delta);
  const double L = p.wheelbase;
  const double num = L * t;
  for (int i = 0; i < 2; ++i) {
    const double den = i == 0 ? L - p.full.ackermann_offset * t : L + p.full.ackermann_offset * t;
    const double hyp2 = num * num + den * den;
    const double inv = 1.0 / std::sqrt(hyp2);
    g.cos_gamma[i] = den * inv;
    g.sin_gamma[i] = num * inv;
    g.dgamma_ddelta[i] = L * L * (1.0 + t * t) / hyp2;
  }
  return g;
}

// The gearbox output speed per unit ratio: the drive-share-weighted wheel speeds (the open
// differentials' kinematics), rad/s.
inline double GearboxOutputSpeed(const Params& p, const StateVector& x) {
  double w = 0.0;
  for (int i = 0; i < kNumWheels; ++i) w += p.full.drive_share[i] * x[sx::kWheelSpin + i];
  return w;
}

// The full model's state for body state `s` (a spawn, or a change of model between steps):
// wheels rolling with the body, springs at their static length, relaxed tires, released brakes,
// the gear the automatic would choose and the engine turning with it, the hand wheel centred.
State InitFullState(const Params& p, const State& s);
// `s` in the layout of p.model (unchanged when it is already).
State ConvertState(const Params& p, const State& s);

}  // namespace vdyn
