// Validation of the full model (VEHICLE_MODEL_FULL, the default) against closed forms and
// published properties of its laws (docs/model.md, "The full model", cites them). Every expected
// value comes from a formula and the parameters, written out here again, never from the code's
// earlier output.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include <gtest/gtest.h>

#include "test_support.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/physics/full_model.h"

namespace vdyn {
namespace {

using Eigen::Vector3d;
using testing::Drive;
using testing::ParamsWith;
using testing::SharedWorld;
constexpr double kDeg = std::numbers::pi / 180.0;

Vector3d BodyAcceleration(const StepRecord& r) {
  return Orientation(r.state.x).toRotationMatrix().transpose() * r.derived.a_WT_W;
}

// --- the brush law, written out again from docs/model.md ---------------------------------------
// Parabolic pressure over the contact length 2a; adhesion limit mu0, sliding friction mu_k;
// z = normalised slip (1 at full sliding). Force and moment over Fz (and a):
double BrushForce(double z, double mu0, double mu_k) {
  if (z >= 1.0) return mu_k;
  return 3.0 * mu0 * z * (1.0 - z) * (1.0 - z) + mu_k * z * z * (3.0 - 2.0 * z);
}
// Aligning moment M / (Fz a) for positive slip (it turns the wheel towards its sliding direction).
double BrushMoment(double z, double mu0, double mu_k) {
  if (z >= 1.0) return 0.0;
  return z * (1.0 - z) * (1.0 - z) * (mu0 * (1.0 - 4.0 * z) + 3.0 * mu_k * z);
}
// The adhesion limit mu0 that puts the force's peak at mu (the peak over z, found by a fine
// search here, not by the derivation the code uses).
double AdhesionLimitFor(double mu, double mu_k) {
  auto peak = [mu_k](double mu0) {
    double best = 0.0;
    for (int i = 0; i <= 20000; ++i) best = std::max(best, BrushForce(i / 20000.0, mu0, mu_k));
    return best;
  };
  double lo = mu_k, hi = 40.0 * mu;
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (peak(mid) < mu ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}
double ArgMax(double (*f)(double, double, double), double mu0, double mu_k) {
  double best = -1.0, arg = 0.0;
  for (int i = 0; i <= 100000; ++i) {
    const double z = i / 100000.0;
    if (f(z, mu0, mu_k) > best) {
      best = f(z, mu0, mu_k);
      arg = z;
    }
  }
  return arg;
}

TEST(FullModelTire, PublishedBrushFormulasAndTheLawsPeak) {
  // With one friction coefficient the law is Fiala's (Pacejka, Tire and Vehicle Dynamics, brush
  // model): F = mu Fz (3z - 3z^2 + z^3), M = mu Fz a z (1 - z)^3, the moment's peak at z = 1/4.
  for (double z : {0.0, 0.1, 0.25, 0.5, 0.9, 0.999}) {
    const double mu = 0.9;
    EXPECT_NEAR(BrushForceRatio(z, mu, mu) * 3.0 * mu * z, mu * (3 * z - 3 * z * z + z * z * z), 1e-12);
    EXPECT_NEAR(BrushTrailRatio(z, mu, mu) * BrushForceRatio(z, mu, mu) * 3.0 * mu * z,
                mu * z * std::pow(1.0 - z, 3), 1e-12);
  }
  EXPECT_NEAR(ArgMax(BrushMoment, 0.9, 0.9), 0.25, 1e-4);
  // The defaults' adhesion limit puts the peak at mu, and the peak slip at 1 / (3 - 2 r).
  const ValidParams p = testing::DefaultParams();
  const double mu_k = p->mu * p->mu_slide_ratio;
  EXPECT_NEAR(p->full.mu_static, AdhesionLimitFor(p->mu, mu_k), 1e-4);
  EXPECT_NEAR(ArgMax(BrushForce, p->full.mu_static, mu_k), p->full.peak_z, 1e-4);
  std::printf("tire: mu %.3f (peak), mu_slide %.3f, adhesion limit mu0 %.4f, peak at z = %.4f, "
              "aligning moment peak at z = %.4f\n",
              p->mu, mu_k, p->full.mu_static, p->full.peak_z,
              ArgMax(BrushMoment, p->full.mu_static, mu_k));
}

// --- parked on a 10 % grade ---------------------------------------------------------------------
// The brakes (LuGre) and the tires (deflection states) hold by stiffness, not by a slip-speed
// regularisation: a parked car does not creep. Issue: no more than 1 mm in 60 s.
double ParkedTravel(double yaw, double brake) {
  const std::shared_ptr<const World> world =
      WorldFromMesh(testing::InclinedPlane(0.10, 300.0), {0.0, 0.0, yaw});
  Simulator sim(world, testing::DefaultParams());
  DriverInput in;
  in.brake = brake;
  sim.SetInput(in);
  Drive(sim, 3000, {});  // settle: the tires and brakes take up the load
  const Vector3d p0 = Position(sim.state().x);
  Drive(sim, 60000, {});
  return (Position(sim.state().x) - p0).norm();
}

TEST(FullModel, ParkedOnA10PercentGradeWithTheBrakeHeldDoesNotCreep) {
  const double along = ParkedTravel(0.0, 0.5);                   // facing up the slope
  const double across = ParkedTravel(std::numbers::pi / 2, 0.5);  // the slope falls to its right
  std::printf("parked on 10 %%: %.3g m along, %.3g m across the slope in 60 s\n", along, across);
  EXPECT_LT(along, 1e-3);
  EXPECT_LT(across, 1e-3);
}

// --- braking ------------------------------------------------------------------------------------
struct StopResult {
  double distance = 0;
  double time = 0;
  double locked_fraction = 0;  // of the steps above 2 m/s, with all wheels turning < 5 % of rolling
};

StopResult BrakeFrom(double v0, bool abs) {
  const ValidParams p = ParamsWith([abs](pb::VehicleParams& m) {
    m.set_abs(abs);
    m.set_brake_force_max(40000.0);  // enough to reach the limit at every wheel
    m.set_cx(0.0);                   // the closed form has no drag
    m.set_rolling_resistance(0.0);   // ... and no rolling resistance
  });
  Simulator sim(SharedWorld("flat"), p);
  sim.Spawn({0.0, 0.0, 0.0}, v0);
  DriverInput in;
  in.brake = 1.0;
  sim.SetInput(in);
  const Vector3d p0 = Position(sim.state().x);
  StopResult out;
  int fast = 0, locked = 0;
  const std::int64_t steps = Drive(sim, 20000, {}, [&](const StepRecord& r) {
    const double v = Velocity(r.state.x).norm();
    if (v > 2.0) {
      ++fast;
      bool all = true;
      for (int w = 0; w < kNumWheels; ++w) {
        all = all && std::abs(r.derived.wheel[w].omega * p->wheel[w].radius) < 0.05 * v;
      }
      locked += all;
    }
    return Velocity(sim.state().x).norm() < 0.01;
  });
  out.distance = (Position(sim.state().x) - p0).norm();
  out.time = steps * sim.h();
  out.locked_fraction = fast > 0 ? static_cast<double>(locked) / fast : 0.0;
  return out;
}

TEST(FullModel, LockedWheelBrakingDistanceIsVSquaredOverTwoMuSlideG) {
  const ValidParams p = testing::DefaultParams();
  const double v0 = 20.0, mu_k = p->mu * p->mu_slide_ratio;
  const StopResult r = BrakeFrom(v0, false);
  const double expect = v0 * v0 / (2.0 * mu_k * p->gravity);
  std::printf("locked wheels from %.0f m/s: %.3f m in %.3f s, closed form %.3f m (%+.2f %%), "
              "locked %.1f %% of the time\n",
              v0, r.distance, r.time, expect, 100.0 * (r.distance / expect - 1.0),
              100.0 * r.locked_fraction);
  EXPECT_GT(r.locked_fraction, 0.95);  // the wheels really locked
  EXPECT_NEAR(r.distance / expect, 1.0, 0.02);
}

TEST(FullModel, AbsBrakingDistanceIsNearVSquaredOverTwoMuPeakG) {
  const ValidParams p = testing::DefaultParams();
  const double v0 = 20.0;
  const StopResult abs = BrakeFrom(v0, true);
  const StopResult locked = BrakeFrom(v0, false);
  // mu is the law's peak (checked against the closed form above): the best any controller can do.
  const double expect = v0 * v0 / (2.0 * p->mu * p->gravity);
  std::printf("ABS from %.0f m/s: %.3f m in %.3f s, peak-mu closed form %.3f m (%+.2f %%); "
              "locked %.3f m\n",
              v0, abs.distance, abs.time, expect, 100.0 * (abs.distance / expect - 1.0),
              locked.distance);
  EXPECT_LT(abs.locked_fraction, 0.05);  // the wheels kept turning
  EXPECT_GE(abs.distance, expect * 0.995);
  EXPECT_LT(abs.distance, expect * 1.06);
  EXPECT_LT(abs.distance, locked.distance * 0.95);
}

// --- wheelspin ------------------------------------------------------------------------------------
// Full throttle from rest on the driven front axle. The largest longitudinal force the axle can
// give is mu Fz_front (mu the peak); spinning, mu_slide Fz_front. With the load transfer of a
// rigid car, a = mu' g c / (L + mu' h) (h the height of T above the ground).
struct LaunchResult {
  double a_mean = 0;         // m/s^2, over the window
  double axle_limit_max = 0; // largest a / (mu Fz_front / m) over the window
  double a_closed = 0;       // the closed form for the window's friction
  double slip_mean = 0;      // front slip ratio
};

LaunchResult Launch(bool traction_control) {
  const ValidParams p = ParamsWith([traction_control](pb::VehicleParams& m) {
    m.set_traction_control(traction_control);
    m.set_cx(0.0);
    m.set_rolling_resistance(0.0);
  });
  Simulator sim(SharedWorld("flat"), p);
  const double h = Position(sim.state().x).z();  // T above the ground at rest
  DriverInput in;
  in.throttle = 1.0;
  sim.SetInput(in);
  LaunchResult out;
  double a_sum = 0.0, slip_sum = 0.0;
  int n = 0;
  Drive(sim, 3500, {}, [&](const StepRecord& r) {
    if (r.t < 0.6 || r.control.gear != 1 || r.control.shifting) return false;
    const double a = BodyAcceleration(r).x();
    const double Fz_front = r.derived.wheel[kLF].Fp + r.derived.wheel[kRF].Fp;
    out.axle_limit_max = std::max(out.axle_limit_max, a / (p->mu * Fz_front / p->mass));
    a_sum += a;
    slip_sum += 0.5 * (r.derived.wheel[kLF].slip_ratio + r.derived.wheel[kRF].slip_ratio);
    ++n;
    return false;
  });
  EXPECT_GT(n, 500);
  out.a_mean = a_sum / n;
  out.slip_mean = slip_sum / n;
  const double mu = traction_control ? p->mu : p->mu * p->mu_slide_ratio;
  out.a_closed = mu * p->gravity * p->c / (p->wheelbase + mu * h);
  return out;
}

TEST(FullModel, WheelspinAccelerationIsBoundedByMuTimesTheDrivenAxlesLoad) {
  const LaunchResult spin = Launch(false);
  const LaunchResult tc = Launch(true);
  std::printf("launch, wheels spinning: a %.3f m/s^2 vs mu_slide closed form %.3f (%+.2f %%), "
              "front slip %.2f, a / (mu Fz_f / m) at most %.4f\n",
              spin.a_mean, spin.a_closed, 100.0 * (spin.a_mean / spin.a_closed - 1.0),
              spin.slip_mean, spin.axle_limit_max);
  std::printf("launch, traction control: a %.3f m/s^2 vs peak-mu closed form %.3f (%+.2f %%), "
              "front slip %.3f\n",
              tc.a_mean, tc.a_closed, 100.0 * (tc.a_mean / tc.a_closed - 1.0), tc.slip_mean);
  EXPECT_GT(spin.slip_mean, 0.5);           // wheelspin happened
  EXPECT_LE(spin.axle_limit_max, 1.0 + 1e-3);  // never beyond mu Fz_front
  EXPECT_LE(tc.axle_limit_max, 1.0 + 1e-3);
  EXPECT_NEAR(spin.a_mean / spin.a_closed, 1.0, 0.03);
  EXPECT_NEAR(tc.a_mean / tc.a_closed, 1.0, 0.06);
  EXPECT_GT(tc.a_mean, spin.a_mean * 1.05);  // holding the peak beats spinning
}

}  // namespace
}  // namespace vdyn
