// Validation of the full model (VEHICLE_MODEL_FULL, the default) against closed forms and
// published properties of its laws (docs/model.md, "The full model", cites them). Every expected
// value comes from a formula and the parameters, written out here again, never from the code's
// earlier output.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "test_support.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/physics/full_model.h"
#include "vdyn/runtime/batch.h"

namespace vdyn {
namespace {

using Eigen::Vector3d;
using testing::Drive;
using testing::ParamsWith;
using testing::SharedWorld;
constexpr double kDeg = std::numbers::pi / 180.0;

Vector3d BodyVelocity(const State& s) {
  return Orientation(s.x).toRotationMatrix().transpose() * Velocity(s.x);
}
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


// --- the tire's forces and moment in a vehicle ----------------------------------------------------
// The brush law with combined slip (docs/model.md), written out again: the transient slips are
// the deflections over the relaxation lengths; C_alpha follows the load as
// sin(2 atan(Fz / (p Fz0))) / sin(2 atan(1 / p)), C_kappa in proportion to it; the force lies
// along (C_kappa kappa', -C_alpha tan alpha') and the moment is the pure-slip trail times Fy.
struct TireExpect {
  double z = 0, Fx = 0, Fy = 0, Mz = 0;
};
TireExpect ExpectedTire(const Params& p, double mu0, int w, const StateVector& x, double Fz) {
  const WheelParams& wp = p.wheel[w];
  const double kappa = x[sx::kDeflectionLong + w] / p.tire_relaxation_long;
  const double tan_alpha = x[sx::kDeflectionLat + w] / p.tire_relaxation_lat;
  const double load = Fz / wp.nominal_load, s = p.tire_load_sensitivity;
  const double C_alpha = wp.cornering_stiffness * std::sin(2.0 * std::atan(load / s)) /
                         std::sin(2.0 * std::atan(1.0 / s));
  const double C_kappa = wp.longitudinal_stiffness * load;
  const double mu_k = p.mu * p.mu_slide_ratio;
  const double phi_x = C_kappa * kappa, phi_y = C_alpha * tan_alpha;
  const double phi = std::hypot(phi_x, phi_y);
  TireExpect e;
  e.z = phi / (3.0 * mu0 * Fz);
  if (phi == 0.0) return e;
  const double F = Fz * BrushForce(e.z, mu0, mu_k);
  e.Fx = F * phi_x / phi;
  e.Fy = -F * phi_y / phi;
  const double a = p.tire_contact_half_length * std::sqrt(load);
  const double trail = e.z < 1.0 ? a * BrushMoment(e.z, mu0, mu_k) / BrushForce(e.z, mu0, mu_k) : 0.0;
  e.Mz = -trail * e.Fy;
  return e;
}

// A ramp steer at 60 km/h with rear-wheel drive (no drive force on the steered wheels): the
// front tires go from linear to full sliding. Their aligning moment peaks first (at the law's
// z of the moment's peak), the side force later (at z*), and at full sliding the moment is gone.
TEST(FullModelTire, AligningMomentPeaksBeforeTheSideForceAndVanishesAtFullSliding) {
  const ValidParams p = ParamsWith([](pb::VehicleParams& m) {
    m.set_drive_front_fraction(0.0);
    m.set_rolling_resistance(0.0);
  });
  const double mu_k = p->mu * p->mu_slide_ratio;
  const double mu0 = AdhesionLimitFor(p->mu, mu_k);
  Simulator sim(SharedWorld("flat"), p);
  sim.Spawn({0, 0, 0}, 60.0 / 3.6);
  double z_at_moment_peak = 0, moment_peak = 0, z_at_force_peak = 0, force_peak = 0;
  double alpha_at_moment_peak = 0, alpha_at_force_peak = 0, z_max = 0, worst = 0;
  double torque_peak = 0, torque_sliding = 0;
  int sliding = 0;
  Drive(sim, 8000,
        [](Simulator& s) {
          DriverInput in;
          in.steer = 0.30 * std::min(1.0, s.time() / 8.0);
          in.cruise_on = true;
          in.cruise_speed = 60.0 / 3.6;
          s.SetInput(in);
        },
        [&](const StepRecord& r) {
          const WheelOutputs& o = r.derived.wheel[kLF];
          const TireExpect e = ExpectedTire(p.get(), mu0, kLF, r.state.x, o.Fp);
          worst = std::max({worst, std::abs(o.Fy - e.Fy) / o.Fp, std::abs(o.Mz - e.Mz) / o.Fp});
          // The moment over Fz a (a = a0 sqrt(Fz / Fz0), the contact half length) and the force
          // over Fz are the law's curves at any load.
          const double a = p->tire_contact_half_length * std::sqrt(o.Fp / p->wheel[kLF].nominal_load);
          const double m = std::abs(o.Mz) / (o.Fp * a), f = std::abs(o.Fy) / o.Fp;
          const double alpha = std::abs(o.slip_angle_t);
          if (m > moment_peak) moment_peak = m, z_at_moment_peak = e.z, alpha_at_moment_peak = alpha;
          if (f > force_peak) force_peak = f, z_at_force_peak = e.z, alpha_at_force_peak = alpha;
          z_max = std::max(z_max, e.z);
          torque_peak = std::max(torque_peak, std::abs(r.derived.steering_torque));
          if (e.z >= 1.0 - 1e-9) {  // full sliding (the deflections stay on z = 1)
            EXPECT_LT(std::abs(o.Mz), 1e-6 * o.Fp);
            torque_sliding = std::max(torque_sliding, std::abs(r.derived.steering_torque));
            ++sliding;
          }
          return false;
        });
  std::printf("ramp steer: |Mz| peak at z %.3f (law %.3f, slip %.2f deg), |Fy| peak at z %.3f "
              "(law %.3f, slip %.2f deg), z reached %.2f; largest deviation from the law %.2g "
              "(per Fz); steering torque %.2f N*m at most, %.2f at full sliding\n",
              z_at_moment_peak, ArgMax(BrushMoment, mu0, mu_k), alpha_at_moment_peak / kDeg,
              z_at_force_peak, ArgMax(BrushForce, mu0, mu_k), alpha_at_force_peak / kDeg, z_max,
              worst, torque_peak, torque_sliding);
  EXPECT_LT(worst, 1e-9);
  EXPECT_GT(sliding, 100);  // the front really slid
  EXPECT_NEAR(z_at_moment_peak, ArgMax(BrushMoment, mu0, mu_k), 0.01);
  EXPECT_NEAR(z_at_force_peak, ArgMax(BrushForce, mu0, mu_k), 0.03);
  EXPECT_LT(alpha_at_moment_peak, 0.5 * alpha_at_force_peak);
  EXPECT_NEAR(force_peak, p->mu, 0.01);
  EXPECT_LT(torque_sliding, 0.6 * torque_peak);  // the wheel goes light when the front slides
}

// Steady cornering: the torque at the hand wheel is the front tires' moments about their
// steering axes through the steering geometry, and the road-wheel angles follow Ackermann.
TEST(FullModel, SteadyCorneringSteeringTorqueIsTheTireMomentsThroughTheGeometry) {
  const ValidParams p = testing::DefaultParams();
  Simulator sim(SharedWorld("flat"), p);
  sim.Spawn({0, 0, 0}, 50.0 / 3.6);
  DriverInput in;
  in.steer = 3.0 * kDeg;
  in.cruise_on = true;
  in.cruise_speed = 50.0 / 3.6;
  sim.SetInput(in);
  Drive(sim, 8000, {});
  const StepRecord& r = sim.last_step();
  const Derived& d = r.derived;
  const double mu0 = AdhesionLimitFor(p->mu, p->mu * p->mu_slide_ratio);
  // Ackermann from its definition: cot(gamma_R) - cot(gamma_L) = ackermann * track / L for a
  // left turn, each around the rack's angle delta: cot(gamma) = cot(delta) -+ k / L.
  const double L = p->wheelbase, k = 0.5 * p->ackermann * (p->b_l + p->b_p);
  auto gamma = [&](double delta, double side) {
    return std::atan(1.0 / (1.0 / std::tan(delta) - side * k / L));
  };
  const double delta = d.steering.angle / p->steering_ratio;
  EXPECT_NEAR(delta, in.steer, 1e-9);
  EXPECT_NEAR(d.wheel[kLF].gamma, gamma(delta, 1.0), 1e-12);
  EXPECT_NEAR(d.wheel[kRF].gamma, gamma(delta, -1.0), 1e-12);
  EXPECT_NEAR(1.0 / std::tan(d.wheel[kRF].gamma) - 1.0 / std::tan(d.wheel[kLF].gamma),
              p->ackermann * (p->b_l + p->b_p) / L, 1e-9);
  double aligning = 0.0, trail = 0.0;
  for (int w : {kLF, kRF}) {
    const WheelOutputs& o = d.wheel[w];
    const double side = w == kLF ? 1.0 : -1.0;
    const double lever = (gamma(delta + 1e-7, side) - gamma(delta - 1e-7, side)) / 2e-7 /
                         p->steering_ratio;
    const TireExpect e = ExpectedTire(p.get(), mu0, w, r.state.x, o.Fp);
    EXPECT_NEAR(o.Mz, e.Mz, 1e-9 * o.Fp);
    EXPECT_NEAR(o.Fy, e.Fy, 1e-9 * o.Fp);
    aligning += e.Mz * lever;
    trail += (-p->caster_trail * e.Fy - side * p->scrub_radius * e.Fx) * lever;
  }
  std::printf("steady turn, 3 deg at 50 km/h: hand-wheel torque %.4f N*m (aligning %.4f + trail "
              "%.4f + friction %.2g + damping %.2g), expected %.4f + %.4f\n",
              d.steering_torque, d.steering.aligning, d.steering.trail, d.steering.friction,
              d.steering.damping, aligning, trail);
  EXPECT_NEAR(d.steering.aligning, aligning, 1e-6 * std::abs(aligning));
  EXPECT_NEAR(d.steering.trail, trail, 1e-6 * std::abs(trail));
  EXPECT_NEAR(d.steering_torque, aligning + trail, 1e-3);  // friction and damping ~0 when steady
  EXPECT_LT(d.steering_torque, -1.0);  // it turns the wheel back towards straight ahead
}

// The side force after a step steer follows the first-order lag of the relaxation length:
// sigma d(tan alpha')/dt + V tan alpha' = V tan alpha, time constant sigma / V. A heavy body on
// soft front tires keeps V and the body's motion constant over the lag (its lateral velocity
// grows by < 0.5 % of the slip's in 6 sigma / V), so the slip itself is a clean step.
TEST(FullModel, SideForceLagsAStepSteerByTheRelaxationTimeConstant) {
  const double V = 10.0;
  const ValidParams p = ParamsWith([](pb::VehicleParams& m) {
    m.set_mass(1e5);
    m.set_ixx(5e6);
    m.set_iyy(6e6);
    m.set_izz(1e7);
    m.set_tire_vertical_stiffness(2e7);
    m.set_steering_follow_frequency(2000.0);
    for (auto* w : {m.mutable_lf(), m.mutable_rf(), m.mutable_lr(), m.mutable_rr()}) {
      w->set_spring_stiffness(3e6);
      w->set_damper_coefficient(2e5);
    }
    const double W = 1e5 * 9.81 / 2.0;
    for (auto* w : {m.mutable_lf(), m.mutable_rf()}) {
      w->set_nominal_load(W * m.c() / (m.b() + m.c()));
      w->set_cornering_stiffness(6500.0);
    }
    for (auto* w : {m.mutable_lr(), m.mutable_rr()}) w->set_nominal_load(W * m.b() / (m.b() + m.c()));
  });
  Simulator sim(SharedWorld("flat"), p);
  sim.Spawn({0, 0, 0}, V);
  Drive(sim, 500, {});
  DriverInput in;
  in.steer = 0.02;
  sim.SetInput(in);
  const double t0 = sim.time();
  std::vector<std::pair<double, double>> fy;  // (t - t0, Fy of LF) at each step's start
  double v_mean = 0.0;
  const int n = static_cast<int>(6.0 * p->tire_relaxation_lat / V / sim.h());  // 6 time constants
  Drive(sim, n, {}, [&](const StepRecord& r) {
    fy.emplace_back(r.t - t0, r.derived.wheel[kLF].Fy);
    v_mean += Velocity(r.state.x).norm() / n;
    return false;
  });
  const double F_end = fy.back().second;

  const double target = (1.0 - std::exp(-1.0)) * F_end;
  double t63 = 0.0;
  for (std::size_t i = 1; i < fy.size(); ++i) {
    if (std::abs(fy[i].second) >= std::abs(target)) {
      const double a = fy[i - 1].second, b = fy[i].second;
      t63 = fy[i - 1].first + (target - a) / (b - a) * (fy[i].first - fy[i - 1].first);
      break;
    }
  }
  // The column follows the step through its critically damped follower (frequency f): the
  // slip step is late by 2 / f on average.
  const double expect = p->tire_relaxation_lat / v_mean + 2.0 / p->steering_follow_frequency;
  std::printf("step steer at %.2f m/s: side force reaches 63 %% after %.2f ms, sigma / V + 2 / f "
              "= %.2f ms (%+.2f %%)\n",
              v_mean, 1e3 * t63, 1e3 * expect, 100.0 * (t63 / expect - 1.0));
  EXPECT_GT(F_end, 100.0);  // a real side force, to the left for a left steer
  EXPECT_NEAR(t63 / expect, 1.0, 0.03);
}

// --- top speed ------------------------------------------------------------------------------------
// Full throttle in top gear: the drive force eta i T(i v / R) / R meets drag plus rolling
// resistance, 1/2 rho cx Sx v^2 + f_rr m g. T is the full-load torque of P = P_max (r + r^2 - r^3).
TEST(FullModel, TopSpeedIsWhereTheDriveForceMeetsDragAndRollingResistance) {
  const ValidParams p = testing::DefaultParams();
  Simulator sim(SharedWorld("flat"), p);
  sim.Spawn({0, 0, 0}, 180.0 / 3.6);
  DriverInput in;
  in.throttle = 1.0;
  sim.SetInput(in);
  Drive(sim, 120000, {});
  const StepRecord& r = sim.last_step();
  const double v = BodyVelocity(sim.state()).x();
  const double expect = testing::ClosedFormTopSpeed(
      p, [&](double) { return p->rolling_resistance * p->mass * p->gravity; });
  std::printf("top speed: %.3f km/h in gear %d at %.0f rpm, closed form %.3f km/h (%+.3f %%)\n",
              3.6 * v, r.control.gear, r.derived.drivetrain.engine_speed * 30.0 / std::numbers::pi,
              3.6 * expect, 100.0 * (v / expect - 1.0));
  EXPECT_EQ(r.control.gear, p->gear_count);
  EXPECT_LT(std::abs(BodyAcceleration(r).x()), 0.01);  // steady
  EXPECT_NEAR(v / expect, 1.0, 0.005);
}

// --- kerbs and travel -----------------------------------------------------------------------------
// Flat ground with a kerb: a box `height` high across the left wheels' path, 1 m long.
std::shared_ptr<const World> KerbWorld(double height) {
  TriangleMesh m;
  m.name = "kerb";
  m.AddQuad(Vector3d(-100, -50, 0), Vector3d(300, -50, 0), Vector3d(300, 50, 0), Vector3d(-100, 50, 0));
  m.AddBox(Vector3d(30.0, 0.0, 0.0), Vector3d(31.0, 20.0, height));
  return WorldFromMesh(std::move(m), {0.0, 0.0, 0.0});
}

TEST(FullModel, AKerbAt30KmhGivesABoundedImpactAndASteeringKick) {
  const ValidParams p = testing::DefaultParams();
  Simulator sim(KerbWorld(0.10), p);
  sim.Spawn({0.0, 0.0, 0.0}, 30.0 / 3.6);
  DriverInput in;
  in.cruise_on = true;
  in.cruise_speed = 30.0 / 3.6;
  sim.SetInput(in);
  double ax_min = 0, ax_max = 0, kick = 0, calm = 0, top_z = 0;
  int kerb_steps = 0;
  const double g = p->gravity;
  Drive(sim, 8000, {}, [&](const StepRecord& r) {
    const double ax = BodyAcceleration(r).x();
    const double x = Position(r.state.x).x();
    bool kerb = false;
    for (int w = 0; w < kNumWheels; ++w) {
      const WheelOutputs& o = r.derived.wheel[w];
      kerb = kerb || o.kerb;
      // A vertical face is never taken for ground: the normal of a trace's contact is upright.
      if (o.contact && !o.kerb) {
        EXPECT_GT(o.n_W.z(), Terrain::kSteepNormalZ) << "t " << r.t;
      }
      EXPECT_GE(o.lS, p->wheel[w].min_length - 1e-3);
      EXPECT_LE(o.lS, p->wheel[w].max_length + 1e-3);
    }
    if (r.t > 1.0) {  // after the spawn settled
      ax_min = std::min(ax_min, ax);
      ax_max = std::max(ax_max, ax);
    }
    if (x > 25.0 && x < 34.0) kick = std::max(kick, std::abs(r.derived.steering_torque));
    if (r.t > 1.0 && x < 25.0) calm = std::max(calm, std::abs(r.derived.steering_torque));
    const WheelOutputs& lf = r.derived.wheel[kLF];
    if (lf.p_B_W.x() > 30.4 && lf.p_B_W.x() < 30.7) top_z = std::max(top_z, lf.p_B_W.z());
    kerb_steps += kerb;
    return false;
  });
  std::printf("kerb 10 cm at 30 km/h: longitudinal acceleration %.2f .. %.2f g, steering torque "
              "up to %.2f N*m at the kerb (%.3f before), %d steps on an edge, left front wheel on top at "
              "z = %.3f m\n",
              ax_min / g, ax_max / g, kick, calm, kerb_steps, top_z);
  EXPECT_GT(kerb_steps, 10);               // the edges were found and carried load
  EXPECT_LT(ax_min, -0.2 * g);             // a longitudinal impact ...
  EXPECT_GT(ax_min, -3.0 * g);             // ... but no spike above a few g
  EXPECT_LT(ax_max, 3.0 * g);
  EXPECT_GT(kick, 5.0 * std::max(calm, 0.2));  // a steering kick
  EXPECT_NEAR(top_z, 0.10, 0.01);          // the left wheels climbed onto it
  EXPECT_GT(Position(sim.state().x).x(), 45.0);
}

// The jump on facility at 50 km/h: the travel stays between the stops (the paper's model lets a
// spring reach a negative length), the landing force stays bounded.
TEST(FullModel, SuspensionTravelStaysBetweenTheStopsThroughAJump) {
  const auto world = SharedWorld("facility");
  const ValidParams p = testing::DefaultParams();
  Simulator sim(world, p);
  const Vector3d ramp = world->LandmarkAt("jump_ramp_a");
  sim.Spawn({ramp.x() - 60.0, ramp.y(), 0.0}, 50.0 / 3.6);
  DriverInput in;
  in.cruise_on = true;
  in.cruise_speed = 50.0 / 3.6;
  sim.SetInput(in);
  double ls_min = 1e9, ls_max = -1e9, fp_max = 0.0, airborne = 0.0;
  Drive(sim, 12000, {}, [&](const StepRecord& r) {
    bool air = true;
    for (int w = 0; w < kNumWheels; ++w) {
      const WheelOutputs& o = r.derived.wheel[w];
      ls_min = std::min(ls_min, o.lS - p->wheel[w].min_length);
      ls_max = std::max(ls_max, o.lS - p->wheel[w].max_length);
      fp_max = std::max(fp_max, o.Fp);
      air = air && !o.contact;
    }
    airborne += air ? sim.h() : 0.0;
    return false;
  });
  std::printf("jump: %.2f s airborne, travel within [min %+.4f, max %+.4f] m of the stops, "
              "largest tire load %.1f kN\n",
              airborne, ls_min, ls_max, fp_max / 1000.0);
  EXPECT_GT(airborne, 0.3);
  EXPECT_GE(ls_min, -1e-3);
  EXPECT_LE(ls_max, 1e-3);
  EXPECT_LT(fp_max, 20.0 * StaticWheelLoad(p, kLF));
  EXPECT_GT(Position(sim.state().x).x(), ramp.x() + 50.0);
}

// --- steering -------------------------------------------------------------------------------------
TEST(FullModel, AReleasedWheelSelfCentresAtSpeedAndStaysWhereItIsAtRest) {
  auto release = [](double speed) {
    Simulator sim(SharedWorld("flat"), testing::DefaultParams());
    sim.Spawn({0, 0, 0}, speed);
    DriverInput in;
    in.steer_mode = SteerMode::kHandWheel;
    in.steer = 0.8;  // 46 degrees at the hand wheel
    in.cruise_on = speed > 0.0;
    in.cruise_speed = speed;
    sim.SetInput(in);
    Drive(sim, 2000, {});
    const double held = sim.state().x[sx::kHandWheel];
    in.steer_mode = SteerMode::kHandsOff;
    sim.SetInput(in);
    Drive(sim, 3000, {});
    return std::make_pair(held, sim.state().x[sx::kHandWheel]);
  };
  const auto [held_fast, free_fast] = release(60.0 / 3.6);
  const auto [held_rest, free_rest] = release(0.0);
  std::printf("hands off: at 60 km/h the hand wheel went from %.3f to %.4f rad in 3 s; at rest "
              "from %.3f to %.4f rad\n",
              held_fast, free_fast, held_rest, free_rest);
  EXPECT_NEAR(held_fast, 0.8, 1e-3);
  EXPECT_LT(std::abs(free_fast), 0.05);       // back near the centre
  EXPECT_NEAR(free_rest, held_rest, 0.02);    // column friction holds it at rest
}

// --- drivetrain -----------------------------------------------------------------------------------
TEST(FullModel, TheAutomaticShiftsUpAtItsSpeedAndTheDriversGearIsObeyed) {
  const ValidParams p = testing::DefaultParams();
  const double rpm = 60.0 / (2.0 * std::numbers::pi);
  Simulator sim(SharedWorld("flat"), p);
  DriverInput in;
  in.throttle = 1.0;
  sim.SetInput(in);
  int gear = 1, highest = 1;
  double rpm_before = 0.0;
  std::vector<double> upshift_rpm;
  Drive(sim, 30000, {}, [&](const StepRecord& r) {
    if (r.control.gear > gear) upshift_rpm.push_back(rpm_before);
    EXPECT_GE(r.control.gear, gear);  // full throttle: never down
    gear = r.control.gear;
    highest = std::max(highest, gear);
    rpm_before = r.derived.drivetrain.engine_speed * rpm;
    return false;
  });
  ASSERT_GE(highest, 5);
  for (double u : upshift_rpm) EXPECT_NEAR(u, p->shift_up_rpm, 60.0);
  // The driver's gear: third at 60 km/h; the engine turns with the wheels through its ratio.
  in = DriverInput{};
  in.gear = 3;
  in.cruise_on = true;
  in.cruise_speed = 60.0 / 3.6;
  sim.Spawn({0, 0, 0}, 60.0 / 3.6);
  sim.SetInput(in);
  Drive(sim, 3000, {});
  const StepRecord& r = sim.last_step();
  EXPECT_EQ(r.control.gear, 3);
  EXPECT_FALSE(r.control.automatic);
  const double w_wheels = 0.5 * (r.derived.wheel[kLF].omega + r.derived.wheel[kRF].omega);
  EXPECT_NEAR(r.derived.drivetrain.engine_speed / w_wheels, p->full.gear_ratio[3] * p->final_drive_ratio,
              0.01 * p->full.gear_ratio[3] * p->final_drive_ratio);
  // Automatic, reverse: a negative throttle from rest drives backwards in gear -1.
  in = DriverInput{};
  in.throttle = -0.5;
  sim.Spawn({0, 0, 0}, 0.0);
  sim.SetInput(in);
  Drive(sim, 3000, {});
  EXPECT_EQ(sim.last_step().control.gear, -1);
  EXPECT_LT(BodyVelocity(sim.state()).x(), -1.0);
  // The clutch pedal down: the engine revs, the car stays.
  in = DriverInput{};
  in.throttle = 1.0;
  in.clutch = 1.0;
  sim.Spawn({0, 0, 0}, 0.0);
  sim.SetInput(in);
  Drive(sim, 2000, {});
  EXPECT_GT(sim.last_step().derived.drivetrain.engine_speed * rpm, 6000.0);
  EXPECT_LT(Velocity(sim.state().x).norm(), 0.05);
}

// A slow circle: an open differential lets the inner driven wheel turn slower than the outer,
// as their paths ask; a locked one turns both at one speed.
TEST(FullModel, OpenDifferentialWheelsFollowTheirPathsALockedOneTurnsThemAlike) {
  auto circle = [](pb::Differential diff) {
    Simulator sim(SharedWorld("flat"),
                  ParamsWith([diff](pb::VehicleParams& m) { m.set_differential(diff); }));
    sim.Spawn({0, 0, 0}, 5.0);
    DriverInput in;
    in.steer = 0.25;
    in.cruise_on = true;
    in.cruise_speed = 5.0;
    sim.SetInput(in);
    Drive(sim, 8000, {});
    return sim.last_step().derived;
  };
  const Derived open = circle(pb::DIFFERENTIAL_OPEN);
  const Derived locked = circle(pb::DIFFERENTIAL_LOCKED);
  const double R = testing::DefaultParams()->wheel[kLF].radius;
  std::printf("circle: open diff omega L/R %.4f (paths %.4f); locked %.4f\n",
              open.wheel[kLF].omega / open.wheel[kRF].omega,
              open.wheel[kLF].v_long / open.wheel[kRF].v_long,
              locked.wheel[kLF].omega / locked.wheel[kRF].omega);
  EXPECT_LT(open.wheel[kLF].omega, 0.97 * open.wheel[kRF].omega);  // the inner wheel is slower
  EXPECT_NEAR(open.wheel[kLF].omega * R / open.wheel[kLF].v_long, 1.0, 0.01);
  EXPECT_NEAR(open.wheel[kRF].omega * R / open.wheel[kRF].v_long, 1.0, 0.01);
  EXPECT_EQ(locked.wheel[kLF].omega, locked.wheel[kRF].omega);
}

TEST(FullModel, TheHandbrakeLocksTheRearWheels) {
  Simulator sim(SharedWorld("flat"), testing::DefaultParams());
  sim.Spawn({0, 0, 0}, 50.0 / 3.6);
  DriverInput in;
  in.handbrake = 1.0;
  sim.SetInput(in);
  Drive(sim, 500, {});
  const Derived& d = sim.last_step().derived;
  const double v = Velocity(sim.state().x).norm();
  EXPECT_GT(v, 5.0);
  EXPECT_LT(std::abs(d.wheel[kLR].omega), 0.05 * v);
  EXPECT_LT(std::abs(d.wheel[kRR].omega), 0.05 * v);
  EXPECT_GT(d.wheel[kLF].omega * testing::DefaultParams()->wheel[kLF].radius, 0.9 * v);
}

// --- properties over the demo drive -----------------------------------------------------------------
TEST(FullModelProperties, NoTireForceExceedsMuTimesItsLoadOverTheDemoDrive) {
  const ValidParams p = testing::DefaultParams();
  Simulator sim(SharedWorld("facility"), p);
  const Maneuver m = Maneuver::Parse(DemoManeuverCsv(), "demo");
  int checked = 0;
  Drive(sim, static_cast<std::int64_t>(m.end_time() / sim.h()),
        [&m](Simulator& s) { s.SetInput(FromManeuver(m.At(s.time()))); },
        [&](const StepRecord& r) {
          for (const WheelOutputs& w : r.derived.wheel) {
            const Vector3d tangential = w.F_W - w.F_W.dot(w.n_W) * w.n_W;
            EXPECT_LE(tangential.norm(), p->mu * w.Fp * (1.0 + 1e-9) + 1e-9);
            EXPECT_NEAR(w.F_W.dot(w.n_W), w.Fp, 1e-9 * (1.0 + w.Fp));
            ++checked;
          }
          return false;
        });
  EXPECT_GT(checked, 100000);
}

// The largest step the default parameters resolve (MaxResolvedStep: the tyres' relaxation at the
// fastest spawn speed, just inside a rear wheel held by the foot brake and the handbrake,
// docs/model.md 8.6; bench/step_sweep finds the demo drive stable to 5 ms) is stable: the demo
// drive at that step stays finite, keeps its peak tire load and body rate within 1.5x of the 1 ms
// run's, the braked car ends at rest, and then stays at rest, finite, with both brakes held.
TEST(FullModelProperties, DemoDriveStableAtTheLargestResolvedStep) {
  const Maneuver m = Maneuver::Parse(DemoManeuverCsv(), "demo");
  const std::int64_t largest_ns =
      static_cast<std::int64_t>(std::floor(MaxResolvedStep(testing::DefaultParams()) * 1e6)) * 1000;
  ASSERT_GT(largest_ns, 3'000'000);  // vdyn steps at 1 ms: well inside
  auto run = [&m](std::int64_t step_ns, double* max_Fp, double* max_rate) {
    SimConfig cfg;
    cfg.step_ns = step_ns;
    Simulator sim(SharedWorld("facility"), testing::DefaultParams(), cfg);
    Drive(sim, std::llround(m.end_time() / sim.h()),
          [&m](Simulator& s) { s.SetInput(FromManeuver(m.At(s.time()))); },
          [&](const StepRecord& r) {
            for (const WheelOutputs& w : r.derived.wheel) *max_Fp = std::max(*max_Fp, w.Fp);
            *max_rate = std::max(*max_rate, r.derived.w_eff_B.norm());
            return false;
          });
    const double end_speed = Velocity(sim.state().x).norm();
    DriverInput held;
    held.brake = 1.0;
    held.handbrake = 1.0;
    Drive(sim, std::llround(2.0 / sim.h()), [&held](Simulator& s) { s.SetInput(held); });
    EXPECT_TRUE(sim.state().x.allFinite()) << step_ns;
    EXPECT_LT(Velocity(sim.state().x).norm(), 0.01) << step_ns;
    return end_speed;
  };
  double fp1 = 0, rate1 = 0, fp_max = 0, rate_max = 0;
  run(1'000'000, &fp1, &rate1);
  const double end_speed = run(largest_ns, &fp_max, &rate_max);
  EXPECT_LT(end_speed, 0.01);
  EXPECT_LT(fp_max, 1.5 * fp1);
  EXPECT_LT(rate_max, 1.5 * rate1);
}

TEST(FullModelProperties, TheModelCanChangeBetweenSteps) {
  Simulator sim(SharedWorld("flat"), testing::PaperParams());
  sim.Spawn({0, 0, 0}, 10.0);
  Drive(sim, 500, {});
  EXPECT_EQ(sim.state().model, VehicleModel::kPaper);
  sim.SetParams(testing::DefaultParams());  // to the full model: wheels rolling with the body
  EXPECT_EQ(sim.state().model, VehicleModel::kFull);
  const double v = BodyVelocity(sim.state()).x();
  EXPECT_NEAR(sim.state().x[sx::kWheelSpin + kLR] * sim.params().wheel[kLR].radius, v, 0.01 * v);
  Drive(sim, 2000, {});
  EXPECT_GT(BodyVelocity(sim.state()).x(), 8.0);
  sim.SetParams(testing::PaperParams());
  EXPECT_EQ(sim.state().model, VehicleModel::kPaper);
  for (int i = kPaperStateSize; i < kStateSize; ++i) EXPECT_EQ(sim.state().x[i], 0.0);
  Drive(sim, 500, {});
}

TEST(FullModelProperties, ThePaperModelReadsAHandWheelAngleThroughTheSteeringRatio) {
  const ValidParams p = testing::PaperParams();
  Simulator sim(SharedWorld("flat"), p);
  DriverInput in;
  in.steer_mode = SteerMode::kHandWheel;
  in.steer = 0.9;
  sim.SetInput(in);
  ASSERT_EQ(sim.Step(), StepStatus::kOk);
  EXPECT_DOUBLE_EQ(sim.last_step().control.gamma, 0.9 / p->steering_ratio);
  in.steer_mode = SteerMode::kHandsOff;
  sim.SetInput(in);
  ASSERT_EQ(sim.Step(), StepStatus::kOk);
  EXPECT_EQ(sim.last_step().control.gamma, 0.0);
}

}  // namespace
}  // namespace vdyn

namespace vdyn {
namespace {

// This model has no contact of the body with the ground: a car that rolls over (mu 3, a 30 degree
// step of the road wheels at 60 km/h) fell through the ground for ever and a batch ended with exit
// 0 kilometres underground. The step that takes its centre under the ground (no wheel touching,
// nothing below, the surface above) is refused: the state stays at x_n and the step says why.
TEST(FullModelProperties, ARolledOverCarIsStoppedAtTheGroundNotLetFallThroughIt) {
  const ValidParams params = testing::ParamsWith([](pb::VehicleParams& m) { m.set_mu(3.0); });
  const Maneuver m = Maneuver::Parse(
      "t_s,steer_deg,throttle,brake,cruise_kmh\n0,0,0,0,60\n3,0,0,0,60\n3.5,30,0,0,60\n", "roll");
  Simulator sim(testing::SharedWorld("flat"), params);
  sim.Spawn({0.0, 0.0, 0.0});
  StepStatus status = StepStatus::kOk;
  double lowest_z = 1e9, largest_roll = 0;
  for (int k = 0; k < 20'000 && status == StepStatus::kOk; ++k) {
    sim.SetInput(FromManeuver(m.At(sim.time())));
    status = sim.Step();
    lowest_z = std::min(lowest_z, Position(sim.state().x).z());
    largest_roll = std::max(largest_roll, std::abs(RollPitchYaw(Orientation(sim.state().x)).x()));
  }
  ASSERT_EQ(status, StepStatus::kUnderGround);
  EXPECT_EQ(sim.under_ground_steps(), 1u);
  EXPECT_GT(largest_roll, 1.5);  // it did roll over (past 86 degrees)
  EXPECT_GT(lowest_z, -0.5);     // kept at the ground, not kilometres under it
  EXPECT_TRUE(sim.state().x.allFinite());
  // A batch says so and fails (exit 1 from vdyn-server --batch).
  Simulator again(testing::SharedWorld("flat"), params);
  again.Spawn({0.0, 0.0, 0.0});
  BatchOptions o;
  o.duration = 20.0;
  const BatchSummary s = RunBatch(again, m, o, nullptr);
  EXPECT_FALSE(s.ok);
  EXPECT_THAT(s.error, ::testing::HasSubstr("the vehicle stopped at t = "));
  EXPECT_THAT(s.error, ::testing::HasSubstr("(step "));
  EXPECT_THAT(s.error, ::testing::HasSubstr("): it fell through the ground (its wheels off"));
  EXPECT_THAT(s.error, ::testing::HasSubstr("this model has no contact of the body with the ground"));
}

// A live change the model cannot carry: springs made 3000 times stiffer while compressed under the
// old rate (1e8 N/m, within its range) push the car away at once; in a live session the states on
// the way reached 7.6e7 km/h and 8.9 km in a step, all published and kept, before one went
// non-finite. A step whose state is faster than any vehicle, or spins faster than any, is
// discarded (kRunaway), as a non-finite one is.
TEST(FullModelProperties, AStateThatRunsAwayIsDiscardedNotPublished) {
  Simulator sim(testing::SharedWorld("flat"), ParamsWith([](pb::VehicleParams&) {}));
  sim.Spawn({0.0, 0.0, 0.0}, 15.0);
  for (int k = 0; k < 200; ++k) ASSERT_EQ(sim.Step(), StepStatus::kOk);
  sim.SetParams(ParamsWith([](pb::VehicleParams& m) {
    for (auto* w : {m.mutable_lf(), m.mutable_rf(), m.mutable_lr(), m.mutable_rr()})
      w->set_spring_stiffness(1e8);
  }));
  double fastest = 0.0;
  int contained = 0, runaway = 0;
  for (int k = 0; k < 3000; ++k) {
    const StepStatus status = sim.Step();
    contained += status != StepStatus::kOk ? 1 : 0;
    runaway += status == StepStatus::kRunaway ? 1 : 0;
    ASSERT_TRUE(sim.state().x.allFinite());
    fastest = std::max(fastest, Velocity(sim.state().x).norm());
    if (status != StepStatus::kOk) sim.Spawn({0.0, 0.0, 0.0});  // as a session does
  }
  EXPECT_GT(runaway, 0);
  EXPECT_EQ(sim.runaway_steps(), static_cast<std::uint64_t>(runaway));
  EXPECT_GT(contained, 0);
  EXPECT_LE(fastest, 1000.0);  // never kept faster
}

}  // namespace
}  // namespace vdyn
