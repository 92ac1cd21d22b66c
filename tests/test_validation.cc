// Physics validation of the paper's model against closed forms and properties (issue: foundation
// and physics core). Every test here runs the paper's model (VEHICLE_MODEL_PAPER), as it did when
// it was the only model; the full model's validation is in test_full_model.cc. Every expected
// value here comes from a formula and the parameters, never from earlier output.
#include <algorithm>
#include <bit>
#include <limits>
#include <charconv>
#include <cmath>
#include <numbers>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Geometry>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "vdyn/bridge/convert.h"
#include "vdyn/runtime/batch.h"
#include "vdyn/physics/drivers.h"
#include "vdyn/io/csv.h"
#include "vdyn/io/shortest_double.h"
#include "vdyn/runtime/csv_pipe.h"
#include "vdyn/io/maneuver.h"
#include "test_support.h"

namespace vdyn {
namespace {

using Eigen::Vector3d;
using testing::Drive;
using ::testing::HasSubstr;
using testing::SharedWorld;
constexpr double kDeg = std::numbers::pi / 180.0;

// The paper's model with the default parameters, and with `edit` applied.
ValidParams PaperDefaults() { return testing::PaperParams(); }
ValidParams ParamsWith(const std::function<void(pb::VehicleParams&)>& edit) {
  return testing::PaperParamsWith(edit);
}

Vector3d BodyVelocity(const State& s) {
  return Orientation(s.x).toRotationMatrix().transpose() * Velocity(s.x);
}

// --- heave -----------------------------------------------------------------------------------
// Four equal springs k and dampers c under a body of mass m with T midway between the axles
// (b = c, bL = bP), so heave does not couple into pitch or roll. Released 3 cm above equilibrium
// it is the damped oscillator  m z'' + 4c z' + 4k z = 0:
//   z(t) = z0 e^(-zeta wn t) (cos wd t + zeta wn / wd sin wd t),  wn = sqrt(4k/m),
//   zeta = 4c / (2 sqrt(4k m)),  wd = wn sqrt(1 - zeta^2).
TEST(Validation, HeaveFollowsTheDampedOscillator) {
  const double k = 30000.0, c = 1500.0, z0 = 0.03;
  const ValidParams p = ParamsWith([&](pb::VehicleParams& m) {
    m.set_b(1.35);
    m.set_c(1.35);
    for (auto* w : {m.mutable_lf(), m.mutable_rf(), m.mutable_lr(), m.mutable_rr()}) {
      w->set_spring_stiffness(k);
      w->set_damper_coefficient(c);
    }
  });
  Simulator sim(SharedWorld("flat"), p);
  State s = sim.state();
  // Equilibrium height from the parameters: each spring carries m g / 4.
  const WheelParams& w = p->wheel[kLF];
  const double z_eq = w.radius + (w.free_length - p->mass * p->gravity / (4.0 * k)) + w.z_offset;
  ASSERT_NEAR(Position(s.x).z(), z_eq, 1e-12);
  s.x[sx::kP + 2] = z_eq + z0;
  sim.SetState(s);

  const double wn = std::sqrt(4.0 * k / p->mass);
  const double zeta = 4.0 * c / (2.0 * std::sqrt(4.0 * k * p->mass));
  const double wd = wn * std::sqrt(1.0 - zeta * zeta);
  double max_err = 0.0, min_z = 1e9;
  Drive(sim, 4000, {}, [&](const StepRecord& r) {
    const double t = r.t + sim.h();  // the state after the step
    const double z = Position(sim.state().x).z() - z_eq;
    const double expect =
        z0 * std::exp(-zeta * wn * t) * (std::cos(wd * t) + zeta * wn / wd * std::sin(wd * t));
    max_err = std::max(max_err, std::abs(z - expect));
    min_z = std::min(min_z, z);
    for (const auto& wo : r.derived.wheel) EXPECT_TRUE(wo.contact);
    return false;
  });
  // It really oscillated: the first undershoot is z0 exp(-zeta pi / sqrt(1 - zeta^2)) = 0.49 z0.
  EXPECT_LT(min_z, -0.45 * z0);
  EXPECT_LT(max_err, 0.005 * z0);      // within 0.5 % of the amplitude
  std::printf("heave: wn %.4f rad/s, zeta %.4f, max |z - closed form| %.3g m (%.4f %% of z0)\n", wn,
              zeta, max_err, 100.0 * max_err / z0);
  const Vector3d rpy = RollPitchYaw(Orientation(sim.state().x));
  EXPECT_LT(rpy.head<2>().norm(), 1e-9);  // no pitch or roll
}

// --- coasting with drag only -------------------------------------------------------------------
// m v' = -(1/2 rho cx Sx) v^2  =>  v(t) = v0 / (1 + (1/2 rho cx Sx) v0 t / m).
TEST(Validation, CoastingWithDragMatchesClosedForm) {
  const ValidParams p = ParamsWith([](pb::VehicleParams& m) { m.set_rolling_resistance(0.0); });
  Simulator sim(SharedWorld("flat"), p);
  const double v0 = 30.0;
  sim.Spawn({0.0, 0.0, 0.3}, v0);
  const double kd = 0.5 * p->rho * p->cx * p->sx;
  double max_rel = 0.0;
  Drive(sim, 30000, {}, [&](const StepRecord& r) {
    const double t = r.t + sim.h();
    const double v = Velocity(sim.state().x).norm();
    const double expect = v0 / (1.0 + kd * v0 * t / p->mass);
    max_rel = std::max(max_rel, std::abs(v - expect) / expect);
    return false;
  });
  const double v_end = Velocity(sim.state().x).norm();
  EXPECT_LT(v_end, 0.85 * v0);      // drag really acted (closed form: 0.805 v0 at 30 s)
  EXPECT_LT(max_rel, 0.005);        // within 0.5 %
  std::printf("coasting: v(30 s) %.4f m/s, max relative error %.3g %%\n", v_end, 100.0 * max_rel);
}

// --- RK4's observed order -----------------------------------------------------------------------
// Halving h must divide the global error by 2^4; the observed order log2(e(h)/e(h/2)) is 4 +- 0.2.
StateVector RunWithStep(std::int64_t step_ns, double t_end, const ValidParams& p, const State& start,
                        const DriverInput& input) {
  SimConfig cfg;
  cfg.step_ns = step_ns;
  Simulator sim(SharedWorld("flat"), p, cfg);
  sim.SetState(start);
  sim.SetInput(input);
  const auto n = static_cast<std::int64_t>(std::llround(t_end / sim.h()));
  for (std::int64_t i = 0; i < n; ++i) EXPECT_EQ(sim.Step(), StepStatus::kOk);
  return sim.state().x;
}

void ExpectFourthOrder(const ValidParams& p, const State& start, const DriverInput& input,
                       double t_end) {
  const StateVector ref = RunWithStep(250'000, t_end, p, start, input);  // h = 0.25 ms
  double err[3];
  const std::int64_t steps_ns[3] = {16'000'000, 8'000'000, 4'000'000};
  for (int i = 0; i < 3; ++i) {
    err[i] = (RunWithStep(steps_ns[i], t_end, p, start, input) - ref).norm();
  }
  for (int i = 0; i < 2; ++i) {
    const double order = std::log2(err[i] / err[i + 1]);
    std::printf("rk4: h %g -> %g ms, errors %.3g -> %.3g, observed order %.3f\n",
                steps_ns[i] * 1e-6, steps_ns[i + 1] * 1e-6, err[i], err[i + 1], order);
    EXPECT_NEAR(order, 4.0, 0.2) << "h = " << steps_ns[i] * 1e-6 << " ms: errors " << err[i]
                                 << " -> " << err[i + 1];
  }
}

TEST(Validation, Rk4ObservedOrderIsFourInHeave) {
  const ValidParams p = PaperDefaults();
  Simulator sim(SharedWorld("flat"), p);
  State s = sim.state();
  s.x[sx::kP + 2] += 0.04;                  // heave, with pitch coupling (b != c)
  ExpectFourthOrder(p, s, DriverInput{}, 0.96);
}

TEST(Validation, Rk4ObservedOrderIsFourWhileCornering) {
  // Full 3-D motion with tire forces: 20 m/s, a 2 degree steer held. Start from the turn already
  // established, so no slip angle crosses zero (the Fiala law's |z| z is only C1 there, which
  // would show up as a local O(h^3) error at the crossing).
  const ValidParams p = PaperDefaults();
  Simulator sim(SharedWorld("flat"), p);
  sim.Spawn({0, 0, 0}, 20.0);
  DriverInput in;
  in.steer = 2.0 * kDeg;
  sim.SetInput(in);
  Drive(sim, 3000, {});
  for (const WheelOutputs& w : sim.last_step().derived.wheel) EXPECT_GT(std::abs(w.slip_angle), 1e-3);
  ExpectFourthOrder(p, sim.state(), in, 0.96);
}

// --- steady-state cornering vs the linear bicycle model ----------------------------------------
// r / delta = V / (L + K V^2),  K = (m / L) (lr / Cf - lf / Cr),  Cf, Cr per axle (2 C_alpha).
void ExpectBicycleGain(double c_front, double c_rear, TireLaw law, double speed) {
  const ValidParams p = ParamsWith([&](pb::VehicleParams& m) {
    m.mutable_lf()->set_cornering_stiffness(c_front);
    m.mutable_rf()->set_cornering_stiffness(c_front);
    m.mutable_lr()->set_cornering_stiffness(c_rear);
    m.mutable_rr()->set_cornering_stiffness(c_rear);
    m.set_tire_law(law == TireLaw::kFiala ? pb::TIRE_LAW_FIALA : pb::TIRE_LAW_LINEAR_SATURATED);
    m.set_drive_front_fraction(0.0);  // rear drive: no drive force on the steered wheels
    m.set_rolling_resistance(0.0);
  });
  const double L = p->wheelbase, Cf = 2.0 * c_front, Cr = 2.0 * c_rear;
  const double K = (p->mass / L) * (p->c / Cf - p->b / Cr);
  // Steer for a lateral acceleration of 0.08 g from the model itself.
  const double ay_target = 0.08 * p->gravity;
  const double delta = ay_target / speed * (L + K * speed * speed) / speed;
  Simulator sim(SharedWorld("flat"), p);
  sim.Spawn({0, 0, 0}, speed);
  DriverInput in;
  in.steer = delta;
  in.cruise_on = true;
  in.cruise_speed = speed;
  sim.SetInput(in);
  double r_sum = 0.0, v_sum = 0.0, ay_max = 0.0;
  int n = 0;
  Drive(sim, 20000, {}, [&](const StepRecord& rec) {
    if (rec.t >= 18.0) {
      r_sum += rec.derived.w_eff_B.z();
      v_sum += Velocity(rec.state.x).norm();
      ay_max = std::max(ay_max, std::abs(
          (Orientation(rec.state.x).toRotationMatrix().transpose() * rec.derived.a_WT_W).y()));
      ++n;
    }
    return false;
  });
  const double r = r_sum / n, V = v_sum / n;
  const double expect = V / (L + K * V * V);
  EXPECT_LE(ay_max, 0.1 * p->gravity);
  std::printf("bicycle: K %.3g rad/(m/s^2), V %.3f m/s, ay_max %.3f g, r/delta %.5f vs %.5f (%+.3f %%)\n",
              K, V, ay_max / p->gravity, r / delta, expect, 100.0 * ((r / delta) / expect - 1.0));
  EXPECT_NEAR((r / delta) / expect, 1.0, 0.02)
      << "K = " << K << ", V = " << V << ", r/delta = " << r / delta << " vs " << expect;
}

TEST(Validation, BicycleModelGainUndersteer) {
  ExpectBicycleGain(55000.0, 80000.0, TireLaw::kFiala, 20.0);
  ExpectBicycleGain(55000.0, 80000.0, TireLaw::kLinearSaturated, 25.0);
}

TEST(Validation, BicycleModelGainOversteer) {
  // K < 0; the critical speed sqrt(L / -K) is ~43 m/s, well above the test speed.
  ExpectBicycleGain(80000.0, 50000.0, TireLaw::kFiala, 20.0);
  ExpectBicycleGain(80000.0, 50000.0, TireLaw::kLinearSaturated, 25.0);
}

// --- static equilibrium -------------------------------------------------------------------------
TEST(Validation, StaticSpringForcesCarryTheWeightSplitByBAndC) {
  const ValidParams p = PaperDefaults();
  Simulator sim(SharedWorld("flat"), p);
  Drive(sim, 5000, {});
  Derived d;
  sim.Forward(d);
  const double front = d.wheel[kLF].Fp + d.wheel[kRF].Fp;
  const double rear = d.wheel[kLR].Fp + d.wheel[kRR].Fp;
  const double W = p->mass * p->gravity;
  EXPECT_NEAR((front + rear) / W, 1.0, 1e-6);
  EXPECT_NEAR(front / W, p->c / p->wheelbase, 2e-3);  // moments about T: Fp_f b = Fp_r c
  EXPECT_NEAR(rear / W, p->b / p->wheelbase, 2e-3);
  EXPECT_NEAR(d.wheel[kLF].Fp, d.wheel[kRF].Fp, 1e-6 * W);  // bL = bP
  EXPECT_LT(Velocity(sim.state().x).norm(), 1e-5);
}

// --- jump ---------------------------------------------------------------------------------------
TEST(Validation, JumpIsBallisticInTheAirAndLandsBounded) {
  const auto world = SharedWorld("facility");
  const ValidParams p = PaperDefaults();
  Simulator sim(world, p);
  const Vector3d ramp = world->LandmarkAt("jump_ramp_a");
  sim.Spawn({ramp.x() - 60.0, ramp.y(), 0.0}, 50.0 / 3.6);
  DriverInput in;
  in.cruise_on = true;
  in.cruise_speed = 50.0 / 3.6;
  sim.SetInput(in);
  int airborne_steps = 0;
  double max_Fp = 0.0;
  Drive(sim, 12000, {}, [&](const StepRecord& r) {
    bool all_air = true;
    for (const WheelOutputs& w : r.derived.wheel) {
      max_Fp = std::max(max_Fp, w.Fp);
      if (!w.contact) {
        // A wheel in the air carries no force at all.
        EXPECT_EQ(w.Fp, 0.0);
        EXPECT_EQ(w.Fh, 0.0);
        EXPECT_EQ(w.Fb, 0.0);
        EXPECT_EQ(w.Fy, 0.0);
      }
      all_air = all_air && !w.contact;
    }
    if (all_air) {
      ++airborne_steps;
      // Ballistic: gravity plus the drag along X_B only.
      const Vector3d drag_W = -r.derived.Da / p->mass *
                              Orientation(r.state.x).toRotationMatrix().col(0);
      EXPECT_NEAR((r.derived.a_WT_W - drag_W).z(), -p->gravity, 1e-9);
      EXPECT_NEAR((r.derived.a_WT_W - drag_W).head<2>().norm(), 0.0, 1e-9);
    }
    return false;
  });
  EXPECT_GT(airborne_steps * sim.h(), 0.3);
  std::printf("jump: %.3f s with all wheels in the air, largest spring force %.1f kN\n",
              airborne_steps * sim.h(), max_Fp / 1000.0);
  // The landing: finite (Drive fails on NaN) and bounded, and the car drives on settled.
  EXPECT_LT(max_Fp, 20.0 * StaticWheelLoad(p, kLF));
  Derived d;
  sim.Forward(d);
  for (const WheelOutputs& w : d.wheel) EXPECT_TRUE(w.contact);
  EXPECT_LT(std::abs(Velocity(sim.state().x).z()), 0.05);
  EXPECT_GT(Position(sim.state().x).x(), ramp.x() + 50.0);
}

// --- glass barrier ------------------------------------------------------------------------------
void DriveIntoBarrier(double heading_deg) {
  const auto world = SharedWorld("facility");
  const ValidParams p = PaperDefaults();
  Simulator sim(world, p);
  const Vector3d inner = world->LandmarkAt("barrier_inner_max");  // north wall at y = inner.y()
  const double yaw = heading_deg * kDeg;
  sim.Spawn({100.0, inner.y() - 30.0, yaw}, 50.0 / 3.6);
  DriverInput in;
  in.cruise_on = true;  // keeps pushing at the wall
  in.cruise_speed = 50.0 / 3.6;
  sim.SetInput(in);
  double max_y = -1e9, max_pen = 0.0;
  bool touched = false;
  Drive(sim, 6000, {}, [&](const StepRecord& r) {
    const Eigen::Matrix3d R = Orientation(r.state.x).toRotationMatrix();
    for (int k = 0; k < Params::kNumProbes; ++k) {
      const Vector3d corner =
          Position(r.state.x) + R * (p->p_TO_B + p->probe_length[k] * p->probe_dir_B[k]);
      max_y = std::max(max_y, corner.y());
    }
    max_pen = std::max(max_pen, r.derived.wall_penetration_max);
    touched = touched || r.derived.wall_contacts > 0;
    return false;
  });
  EXPECT_TRUE(touched);
  std::printf("barrier at %.0f deg: deepest probe %.3f m into the wall, body reached y = %.3f m\n",
              heading_deg, max_pen, max_y);
  // No point of the body box ever reaches the barrier's far face; the body stays inside.
  EXPECT_LT(max_y, inner.y() + world->LandmarkAt("barrier_thickness").y());
  EXPECT_LT(max_pen, 0.35);
  EXPECT_LT(Position(sim.state().x).y(), inner.y());
}

TEST(Validation, BarrierStopsTheCarHeadOnAt50kmh) { DriveIntoBarrier(90.0); }
TEST(Validation, BarrierStopsTheCarAtAnAngleAt50kmh) { DriveIntoBarrier(60.0); }

// --- cruise control -----------------------------------------------------------------------------
void ExpectCruiseHolds(double slope) {
  const ValidParams p = PaperDefaults();
  const std::shared_ptr<const World> world =
      WorldFromMesh(testing::InclinedPlane(slope, 3000.0), {0, 0, 0});
  Simulator sim(world, p);
  const double set = 72.0 / 3.6;
  DriverInput in;
  in.cruise_on = true;
  in.cruise_speed = set;
  sim.SetInput(in);
  bool reached = false;
  double worst_after = 0.0;
  Drive(sim, 60000, {}, [&](const StepRecord&) {
    const double vx = BodyVelocity(sim.state()).x();
    if (!reached && std::abs(vx - set) <= 0.02 * set) reached = true;
    if (reached) worst_after = std::max(worst_after, std::abs(vx - set) / set);
    return false;
  });
  EXPECT_TRUE(reached);
  EXPECT_LT(worst_after, 0.02);
  EXPECT_NEAR(BodyVelocity(sim.state()).x(), set, 0.002 * set);
}

TEST(Validation, CruiseControlReachesAndHoldsOnFlat) { ExpectCruiseHolds(0.0); }
TEST(Validation, CruiseControlHoldsUphill) { ExpectCruiseHolds(0.06); }
TEST(Validation, CruiseControlHoldsDownhill) { ExpectCruiseHolds(-0.06); }

// --- stability on the rough terrain ---------------------------------------------------------------
// Ten simulated minutes on the rough patch: a driver circling the patch centre, step steers every
// 7 s and full braking every 40 s (CircuitDriver). No NaN, bounded forces and rates.
struct RoughDriveStats {
  std::int64_t nonfinite = 0;
  double on_patch_fraction = 0;
  double max_Fp = 0;
  double max_rate = 0;
};

RoughDriveStats RoughDrive(std::int64_t step_ns, double seconds) {
  const auto world = SharedWorld("facility");
  SimConfig cfg;
  cfg.step_ns = step_ns;
  Simulator sim(world, PaperDefaults(), cfg);
  const Vector3d c = world->LandmarkAt("rough_terrain_center");
  const Vector3d lo = world->LandmarkAt("rough_terrain_min");
  const Vector3d hi = world->LandmarkAt("rough_terrain_max");
  CircuitDriver driver;
  driver.center = c.head<2>();
  sim.Spawn({c.x() + driver.radius, c.y(), std::numbers::pi / 2});
  RoughDriveStats st;
  const auto n = static_cast<std::int64_t>(seconds / sim.h());
  std::int64_t on_patch = 0;
  for (std::int64_t i = 0; i < n; ++i) {
    sim.SetInput(driver.Input(sim.state(), sim.time()));
    if (sim.Step() != StepStatus::kOk) {
      ++st.nonfinite;
      break;
    }
    for (const WheelOutputs& w : sim.last_step().derived.wheel) st.max_Fp = std::max(st.max_Fp, w.Fp);
    st.max_rate = std::max(st.max_rate, AngularVelocityB(sim.state().x).norm());
    const Vector3d pos = Position(sim.state().x);
    const bool inside = pos.x() > lo.x() + 6 && pos.x() < hi.x() - 6 && pos.y() > lo.y() + 6 &&
                        pos.y() < hi.y() - 6;
    on_patch += inside ? 1 : 0;
  }
  st.on_patch_fraction = static_cast<double>(on_patch) / static_cast<double>(n);
  return st;
}

// Ten minutes (one under the sanitizers) of circling on the rough patch.
TEST(Validation, MinutesOnRoughTerrainStayFiniteAndBounded) {
  const double seconds = testing::kSanitized ? 60.0 : 600.0;
  const RoughDriveStats st = RoughDrive(1'000'000, seconds);
  EXPECT_EQ(st.nonfinite, 0);
  std::printf("rough: %.1f %% of %.0f s on the patch, largest Fp %.1f kN, largest |w| %.2f rad/s\n",
              100.0 * st.on_patch_fraction, seconds, st.max_Fp / 1000.0, st.max_rate);
  EXPECT_GT(st.on_patch_fraction, 0.95);  // the drive really was on the rough terrain
  EXPECT_LT(st.max_Fp, 40000.0);
  EXPECT_LT(st.max_rate, 3.0);
}

// The documented largest stable step for driving (docs/model.md, bench/step_sweep): the demo
// drive at h = 10 ms stays finite, keeps its peak spring force and body rate within 1.5x of the
// 1 ms run's, and the braked car ends at rest.
TEST(Validation, DemoDriveStableAtTheDocumentedLargestStep) {
  const Maneuver m = Maneuver::Parse(DemoManeuverCsv(), "demo");
  auto run = [&m](std::int64_t step_ns, double* max_Fp, double* max_rate) {
    SimConfig cfg;
    cfg.step_ns = step_ns;
    Simulator sim(SharedWorld("facility"), PaperDefaults(), cfg);
    Drive(sim, std::llround(m.end_time() / sim.h()),
          [&m](Simulator& s) { s.SetInput(FromManeuver(m.At(s.time()))); },
          [&](const StepRecord& r) {
            for (const WheelOutputs& w : r.derived.wheel) *max_Fp = std::max(*max_Fp, w.Fp);
            *max_rate = std::max(*max_rate, r.derived.w_eff_B.norm());
            return false;
          });
    return Velocity(sim.state().x).norm();
  };
  double fp1 = 0, rate1 = 0, fp10 = 0, rate10 = 0;
  run(1'000'000, &fp1, &rate1);
  const double end_speed = run(10'000'000, &fp10, &rate10);
  EXPECT_LT(end_speed, 0.01);
  EXPECT_LT(fp10, 1.5 * fp1);
  EXPECT_LT(rate10, 1.5 * rate1);
}

// --- determinism --------------------------------------------------------------------------------
// A CSV cell is the shortest decimal form that reads back exactly (as std::to_chars writes it),
// whole numbers without a decimal point, no "-0"; and each cell reads back.
TEST(Validation, CsvNumbersAreTheShortestExactForm) {
  auto cell = [](double v) {
    char buf[64];
    return std::string(buf, CsvNumber(buf, buf + sizeof buf, v));
  };
  auto reference = [](double v) {
    char buf[64];
    return std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
  };
  int checked = 0;
  for (int i = -120'000; i <= 120'000; ++i) {
    for (double v : {static_cast<double>(i), i + 0.5, i * 0.001}) {
      if (v == 0.0) continue;
      ASSERT_EQ(cell(v), reference(v)) << v;
      ++checked;
    }
  }
  EXPECT_EQ(cell(0.0), "0");
  EXPECT_EQ(cell(-0.0), "0");  // no "-0" in a spreadsheet
  EXPECT_EQ(cell(100000.0), "1e+05");
  EXPECT_EQ(cell(-99999.0), "-99999");
  EXPECT_EQ(cell(std::nextafter(1e5, 0.0)), reference(std::nextafter(1e5, 0.0)));
  std::mt19937_64 rng(19);
  std::uniform_real_distribution<double> mantissa(-1.0, 1.0);
  std::uniform_int_distribution<int> exponent(-30, 30);
  for (int k = 0; k < 200'000; ++k) {
    const double v = std::ldexp(mantissa(rng), exponent(rng));
    const std::string c = cell(v);
    ASSERT_EQ(c, v == 0.0 ? std::string("0") : reference(v)) << v;
    ASSERT_EQ(std::strtod(c.c_str(), nullptr), v) << c;
  }
  EXPECT_EQ(checked, 3 * 240'001 - 2);  // 0 and 0 * 0.001 skipped
}

// WriteShortestDouble writes what std::to_chars writes (the shortest form that reads back, fixed
// or scientific whichever is shorter, every digit of a whole number beyond 2^53), over random bit
// patterns and where formatters go wrong: powers of two and ten and their neighbours, subnormals,
// the extremes, whole numbers, halves, thousandths; and writes nothing past kShortestDoubleBytes.
TEST(Validation, ShortestDoubleWritesWhatStdToCharsWrites) {
  std::vector<double> values = {0.0, -0.0, std::numeric_limits<double>::max(),
                                -std::numeric_limits<double>::max(),
                                std::numeric_limits<double>::min(),
                                std::numeric_limits<double>::denorm_min(),
                                std::numeric_limits<double>::infinity(),
                                -std::numeric_limits<double>::infinity(),
                                std::numeric_limits<double>::quiet_NaN(), 9007199254740993.0,
                                1e23, 5e-324, 0.1, 0.3, 2.0 / 3.0};
  auto with_neighbours = [&values](double v) {
    values.push_back(v);
    values.push_back(std::nextafter(v, 0.0));
    values.push_back(std::nextafter(v, std::numeric_limits<double>::infinity()));
  };
  for (int e = -1074; e <= 1023; ++e) with_neighbours(std::ldexp(1.0, e));
  for (int e = -323; e <= 308; ++e) with_neighbours(std::strtod(("1e" + std::to_string(e)).c_str(), nullptr));
  for (int i = -100'000; i <= 100'000; ++i) {
    for (double v : {static_cast<double>(i), i + 0.5, i * 0.001, i * 1e-7, i * 1e12}) values.push_back(v);
  }
  std::mt19937_64 rng(2026);
  for (int k = 0; k < 2'000'000; ++k) values.push_back(std::bit_cast<double>(rng()));
  int differ = 0;
  for (const double v : values) {
    char ours[kShortestDoubleBytes + 16], reference[64];
    std::memset(ours, '#', sizeof ours);
    const std::string a(ours, WriteShortestDouble(ours, v));
    const std::string b(reference, std::to_chars(reference, reference + sizeof reference, v).ptr);
    if (a != b && ++differ <= 10) ADD_FAILURE() << "wrote " << a << ", std::to_chars " << b;
    for (int i = kShortestDoubleBytes; i < kShortestDoubleBytes + 16; ++i) {
      ASSERT_EQ(ours[i], '#') << "wrote past kShortestDoubleBytes for " << b;
    }
  }
  EXPECT_EQ(differ, 0) << "of " << values.size();
  EXPECT_GT(values.size(), 3'000'000u);
}

// The demo drive twice, once on another thread with its own world, once with the CSV written on a
// second thread and once all on the stepping thread: byte-identical CSV files.
TEST(Validation, SameManeuverGivesByteIdenticalCsv) {
  testing::TempDir dir;
  const Maneuver m = Maneuver::Parse(DemoManeuverCsv(), "demo");
  auto run = [&m](const std::filesystem::path& out, bool csv_thread, std::uint64_t* hash) {
    std::shared_ptr<const World> world = BuildBuiltinWorld("facility");
    Simulator sim(world, PaperDefaults());
    CsvWriter csv(out);
    BatchOptions o;
    o.duration = m.end_time();
    o.csv_thread = csv_thread;
    const BatchSummary s = RunBatch(sim, m, o, &csv);
    csv.Close();
    *hash = s.final_hash;
  };
  std::uint64_t h1 = 0, h2 = 0;
  run(dir / "a.csv", true, &h1);
  std::thread other([&] { run(dir / "b.csv", false, &h2); });
  other.join();
  const std::string a = testing::ReadFile(dir / "a.csv"), b = testing::ReadFile(dir / "b.csv");
  EXPECT_GT(a.size(), 1000000u);
  EXPECT_TRUE(a == b) << "the two CSV files differ";
  EXPECT_EQ(h1, h2);
}

// The CSV's second thread writes the bytes one thread writes, in order, whoever formats the rows:
// the writer alone, the stepping thread alone (format_here_from 0) or both sharing (the default).
TEST(Validation, CsvPipeWritesTheSameBytesWhoeverFormatsTheRows) {
  testing::TempDir dir;
  const Maneuver m = Maneuver::Parse(DemoManeuverCsv(), "demo");
  Simulator sim(SharedWorld("facility"), PaperDefaults());
  std::vector<StepRecord> records;
  Drive(sim, 3000, [&m](Simulator& s) { s.SetInput(FromManeuver(m.At(s.time()))); },
        [&](const StepRecord& r) {
          records.push_back(r);
          return false;
        });
  ASSERT_EQ(records.size(), 3000u);
  {
    CsvWriter csv(dir / "serial.csv");
    CsvRowFormatter rows(sim.step_ns());
    std::vector<char> line(CsvRowMaxBytes());
    for (const StepRecord& r : records) csv.WriteFormattedRow(line.data(), rows.Format(r, line.data()));
    csv.Close();
  }
  const std::string serial = testing::ReadFile(dir / "serial.csv");
  ASSERT_GT(serial.size(), 3000u * 1000u);
  const std::uint64_t writer_only = CsvPipe::kSlots + 1;  // the ring never holds more than kSlots
  for (const std::uint64_t from : {std::uint64_t{0}, CsvPipe::kSlots / 2, writer_only}) {
    const std::filesystem::path path = dir / ("pipe-" + std::to_string(from) + ".csv");
    CsvWriter csv(path);
    CsvPipe pipe(csv, sim.step_ns(), from);
    for (const StepRecord& r : records) pipe.Push(r);
    pipe.Finish();
    csv.Close();
    EXPECT_EQ(csv.rows(), records.size()) << "format_here_from " << from;
    EXPECT_TRUE(testing::ReadFile(path) == serial) << "format_here_from " << from;
    if (from == 0) {
      EXPECT_EQ(pipe.rows_formatted_by_pusher(), records.size());
    } else if (from == writer_only) {
      EXPECT_EQ(pipe.rows_formatted_by_pusher(), 0u);
    }
  }
}

// --- friction circle, paper yaw mode, containment -----------------------------------------------
// The demo drive (vdyn-input --maneuver demo, scripts/demo.sh's live session) stays on the
// facility's road from its start to its stop: at every step every wheel's contact point (in the
// air off jump ramp A, the point below the wheel) lies on the road's asphalt - the part of the
// road mesh at its full height, read from the world's own meshes (its 0.4 m edges slope down to
// the grass) - and a trace straight down from above it meets the road or what is built on it
// (bumps, washboard, ramp A), never the grass. For the full model (the default) and the paper's.
// (Before: the step steer, 3 degrees held 4 s, turned the car 53 degrees onto the grass.)
TEST(Properties, TheDemoDriveKeepsEveryWheelOnTheFacilitysRoad) {
  const auto world = SharedWorld("facility");
  const Terrain& terrain = world->terrain;
  double top = -std::numeric_limits<double>::infinity();
  for (const TriangleMesh& mesh : terrain.meshes()) {
    if (mesh.kind != SurfaceKind::kRoad) continue;
    for (const Vector3d& v : mesh.vertices_W) top = std::max(top, v.z());
  }
  Eigen::AlignedBox2d asphalt;
  for (const TriangleMesh& mesh : terrain.meshes()) {
    if (mesh.kind != SurfaceKind::kRoad) continue;
    for (const Vector3d& v : mesh.vertices_W) {
      if (v.z() >= top) asphalt.extend(Eigen::Vector2d(v.x(), v.y()));
    }
  }
  ASSERT_FALSE(asphalt.isEmpty());
  ASSERT_GT(asphalt.sizes().x(), 500.0);  // the 524 m test road, 8 m wide
  ASSERT_NEAR(asphalt.sizes().y(), 8.0, 1e-9);
  const Maneuver m = Maneuver::Named("demo");
  for (const bool paper : {false, true}) {
    SCOPED_TRACE(paper ? "paper model" : "full model");
    Simulator sim(world, paper ? PaperDefaults() : testing::DefaultParams());
    int off = 0;
    double margin = std::numeric_limits<double>::infinity();  // nearest approach to an edge, m
    Drive(sim, std::llround(m.end_time() / sim.h()),
          [&m](Simulator& s) { s.SetInput(FromManeuver(m.At(s.time()))); },
          [&](const StepRecord& r) {
            for (std::size_t k = 0; k < r.derived.wheel.size(); ++k) {
              const Vector3d& p = r.derived.wheel[k].p_B_W;
              const Eigen::Vector2d xy(p.x(), p.y());
              const TraceHit hit =
                  terrain.Trace(Vector3d(p.x(), p.y(), p.z() + 2.0), -Vector3d::UnitZ(), 10.0);
              const SurfaceKind kind = hit.hit ? terrain.meshes()[hit.mesh].kind : SurfaceKind::kGround;
              const bool on_road = asphalt.contains(xy) &&
                                   (kind == SurfaceKind::kRoad || kind == SurfaceKind::kObstacle ||
                                    kind == SurfaceKind::kRamp);
              margin = std::min({margin, p.y() - asphalt.min().y(), asphalt.max().y() - p.y(),
                                 p.x() - asphalt.min().x(), asphalt.max().x() - p.x()});
              if (!on_road && ++off <= 3) {
                ADD_FAILURE() << "wheel " << k << " off the road at t = " << r.t
                              << " s: (" << p.x() << ", " << p.y() << ") on "
                              << (hit.hit ? terrain.meshes()[hit.mesh].name : "nothing");
              }
            }
            return false;
          });
    EXPECT_EQ(off, 0);
    std::printf("demo drive (%s): the wheels came within %.2f m of the asphalt's edge\n",
                paper ? "paper model" : "full model", margin);
    EXPECT_GT(Position(sim.state().x).x(), 150.0);  // it drove the road: past the step steer
    EXPECT_LT(Velocity(sim.state().x).norm(), 0.01);  // and stopped on it
  }
}

TEST(Properties, EveryWheelForceStaysInsideTheFrictionCircle) {
  const auto world = SharedWorld("facility");
  const ValidParams p = PaperDefaults();
  Simulator sim(world, p);
  const Maneuver m = Maneuver::Parse(DemoManeuverCsv(), "demo");
  int checked = 0;
  Drive(sim, static_cast<std::int64_t>(m.end_time() / sim.h()),
        [&m](Simulator& s) { s.SetInput(FromManeuver(m.At(s.time()))); },
        [&](const StepRecord& r) {
          for (const WheelOutputs& w : r.derived.wheel) {
            const Vector3d tangential = w.F_W - w.F_W.dot(w.n_W) * w.n_W;
            EXPECT_LE(tangential.norm(), p->mu * w.Fp * (1.0 + 1e-12) + 1e-9);
            EXPECT_NEAR(w.F_W.dot(w.n_W), w.Fp, 1e-9 * (1.0 + w.Fp));  // Fp is the normal force
            ++checked;
          }
          return false;
        });
  EXPECT_GT(checked, 100000);
}

TEST(Properties, PaperYawModeFollowsEquation6AsAYawRate) {
  const ValidParams p = ParamsWith([](pb::VehicleParams& m) { m.set_yaw_mode(pb::YAW_MODE_PAPER); });
  Simulator sim(SharedWorld("flat"), p);
  sim.Spawn({0, 0, 0}, 10.0);
  DriverInput in;
  in.steer = 2.0 * kDeg;
  in.cruise_on = true;
  in.cruise_speed = 10.0;
  sim.SetInput(in);
  Drive(sim, 3000, {}, [&](const StepRecord& r) {
    const double vx = BodyVelocity(r.state).x();
    EXPECT_NEAR(r.derived.w_eff_B.z(), vx * std::sin(in.steer) / p->wheelbase, 1e-12);
    return false;
  });
  // Closed form at constant speed: the heading turns at v sin(gamma) / L, so after 3 s
  // psi = 10 m/s * sin(2 deg) * 3 s / 2.7 m = 0.3877 rad (the speed control holds 10 m/s).
  const double expect = 10.0 * std::sin(in.steer) * 3.0 / p->wheelbase;
  EXPECT_NEAR(RollPitchYaw(Orientation(sim.state().x)).z(), expect, 0.005 * expect);
}

TEST(Properties, NonFiniteInputIsSanitizedAndCounted) {
  Simulator sim(SharedWorld("flat"), PaperDefaults());
  DriverInput in;
  in.steer = std::numeric_limits<double>::quiet_NaN();
  in.throttle = 7.0;
  sim.SetInput(in);
  EXPECT_EQ(sim.sanitized_inputs(), 1u);
  EXPECT_EQ(sim.input().steer, 0.0);
  EXPECT_EQ(sim.input().throttle, 1.0);
  EXPECT_EQ(sim.Step(), StepStatus::kOk);
  EXPECT_TRUE(sim.state().x.allFinite());
}

// The step's invariants (issue 19): each check trips on a crafted bad value and names it, and a
// good step passes them all.
TEST(Invariants, EachCheckTripsOnACraftedBadValue) {
  Simulator sim(SharedWorld("flat"), testing::DefaultParams());
  Drive(sim, 50, {});
  const StepRecord good = sim.last_step();
  EXPECT_EQ(CheckStepInvariants(good, sim.state()), "");
  StepRecord r = good;
  r.state.x.segment<4>(sx::kQ) *= 1.5;
  EXPECT_THAT(CheckStepInvariants(r, sim.state()),
              HasSubstr("invariant: the starting state's quaternion has norm 1.5"));
  State after = sim.state();
  after.x.segment<4>(sx::kQ) *= 1.01;
  EXPECT_THAT(CheckStepInvariants(good, after), HasSubstr("the new state's quaternion has norm"));
  r = good;
  r.derived.wheel[2].Fp = -5.0;
  EXPECT_THAT(CheckStepInvariants(r, sim.state()),
              HasSubstr("invariant: wheel LR: spring force Fp = -5 N < 0"));
  r = good;
  r.derived.a_WT_W.y() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(CheckStepInvariants(r, sim.state()),
              HasSubstr("invariant: a_WT_W = nan is not a finite number"));
  r = good;
  r.derived.wheel[1].slip_ratio = std::numeric_limits<double>::infinity();
  EXPECT_THAT(CheckStepInvariants(r, sim.state()), HasSubstr("RF slip_ratio = inf"));
  r = good;
  r.derived.drivetrain.engine_torque = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(CheckStepInvariants(r, sim.state()), HasSubstr("engine_torque = nan"));
  // A non-finite state is contained (the step discarded), not an invariant that fails.
  r = good;
  r.state.x[sx::kV] = std::numeric_limits<double>::infinity();
  EXPECT_EQ(CheckStepInvariants(r, sim.state()), "");
}

// Debug and sanitizer builds run the checks after every step: a state given with a quaternion of
// norm 1.5 trips the handler on the next step.
TEST(Invariants, TheStepChecksThemInDebugAndSanitizerBuilds) {
  if (!kCheckInvariants) GTEST_SKIP() << "this build does not check invariants (release)";
  static std::vector<std::string> tripped;
  tripped.clear();
  SetInvariantHandler([](const std::string& what) { tripped.push_back(what); });
  Simulator sim(SharedWorld("flat"), testing::DefaultParams());
  Drive(sim, 20, {});
  EXPECT_TRUE(tripped.empty());
  State s = sim.state();
  s.x.segment<4>(sx::kQ) *= 1.5;
  sim.SetState(s);
  EXPECT_EQ(sim.Step(), StepStatus::kOk);
  SetInvariantHandler(nullptr);
  ASSERT_EQ(tripped.size(), 1u);
  EXPECT_THAT(tripped[0], HasSubstr("the starting state's quaternion has norm 1.5"));
}

// The always-on tier (issue 32): each demand trips on a crafted bad value, names it and writes no
// more than its buffer; a good step passes.
TEST(Invariants, EachDemandTripsOnACraftedBadValue) {
  Simulator sim(SharedWorld("flat"), testing::DefaultParams());
  Drive(sim, 50, {});
  const StepRecord good = sim.last_step();
  char why[160] = "";
  EXPECT_TRUE(CheckStepDemands(good, sim.state(), why, sizeof why));
  EXPECT_STREQ(why, "");
  StepRecord r = good;
  r.state.x.segment<4>(sx::kQ) *= 1.5;
  EXPECT_FALSE(CheckStepDemands(r, sim.state(), why, sizeof why));
  EXPECT_THAT(why, HasSubstr("the starting state's quaternion has norm 1.5"));
  State after = sim.state();
  after.x.segment<4>(sx::kQ) *= 1.01;
  EXPECT_FALSE(CheckStepDemands(good, after, why, sizeof why));
  EXPECT_THAT(why, HasSubstr("the new state's quaternion has norm 1.01"));
  r = good;
  r.derived.wheel[3].Fp = -2.0;
  EXPECT_FALSE(CheckStepDemands(r, sim.state(), why, sizeof why));
  EXPECT_THAT(why, HasSubstr("wheel RR: spring force Fp = -2 N"));
  r = good;
  r.derived.wheel[0].Fp = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(CheckStepDemands(r, sim.state(), why, sizeof why));
  EXPECT_THAT(why, HasSubstr("wheel LF: spring force Fp = nan"));
  r = good;
  r.state.x[sx::kP] = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(CheckStepDemands(r, sim.state(), why, sizeof why));
  EXPECT_THAT(why, HasSubstr("the starting state is not finite"));
  char tiny[8];
  EXPECT_FALSE(CheckStepDemands(r, sim.state(), tiny, sizeof tiny));
  EXPECT_EQ(std::strlen(tiny), 7u);
}

// Every build (release too) checks the demands after every step, counts a failure and keeps its
// reason (the server's diagnostics report both): a state given with a quaternion of norm 1.5.
TEST(Invariants, TheStepCountsADemandFailureInEveryBuild) {
  static int handled = 0;
  handled = 0;
  SetInvariantHandler([](const std::string&) { ++handled; });  // debug builds: no abort
  Simulator sim(SharedWorld("flat"), testing::DefaultParams());
  Drive(sim, 20, {});
  EXPECT_EQ(sim.invariant_failures(), 0u);
  EXPECT_STREQ(sim.last_invariant_failure(), "");
  State s = sim.state();
  s.x.segment<4>(sx::kQ) *= 1.5;
  sim.SetState(s);
  EXPECT_EQ(sim.Step(), StepStatus::kOk);
  Drive(sim, 20, {});
  SetInvariantHandler(nullptr);
  EXPECT_EQ(sim.invariant_failures(), 1u);
  EXPECT_THAT(sim.last_invariant_failure(),
              HasSubstr("the starting state's quaternion has norm 1.5"));
  EXPECT_EQ(handled, kCheckInvariants ? 1 : 0);
}

TEST(Properties, NonFiniteStateIsContained) {
  Simulator sim(SharedWorld("flat"), PaperDefaults());
  Drive(sim, 50, {});  // a state with a history: step, cruise integral, motion all non-trivial
  State s = sim.state();
  s.x[sx::kV] = std::numeric_limits<double>::infinity();
  s.cruise_integral = 0.125;
  sim.SetState(s);
  EXPECT_EQ(sim.Step(), StepStatus::kNonFinite);
  EXPECT_EQ(sim.nonfinite_steps(), 1u);
  // The rejected step left the state exactly as it was before it, bit for bit.
  const State& after = sim.state();
  EXPECT_EQ(std::memcmp(after.x.data(), s.x.data(), sizeof(double) * 13), 0);
  EXPECT_EQ(std::memcmp(&after.cruise_integral, &s.cruise_integral, sizeof(double)), 0);
  EXPECT_EQ(after.step, s.step);
  EXPECT_EQ(StateHash(after), StateHash(s));
}

TEST(Properties, ParametersChangeBetweenSteps) {
  Simulator sim(SharedWorld("flat"), PaperDefaults());
  Drive(sim, 1000, {});
  // A heavier car sinks: the new static deflection follows k and the new weight.
  const ValidParams heavy = ParamsWith([](pb::VehicleParams& m) { m.set_mass(2000.0); });
  sim.SetParams(heavy);
  Drive(sim, 8000, {});
  Derived d;
  sim.Forward(d);
  double sum = 0.0;
  for (const auto& w : d.wheel) sum += w.Fp;
  EXPECT_NEAR(sum, heavy->mass * heavy->gravity, 1e-3 * heavy->mass * heavy->gravity);
}

}  // namespace
}  // namespace vdyn

namespace vdyn {
namespace {

using Eigen::Vector3d;
using testing::Drive;
using ::testing::HasSubstr;
using testing::SharedWorld;

// --- the edge of the physics: starts that cannot be, contacts that cannot blow up ---------------

TEST(Spawn, InsideAWallOrAPostIsRefusedWithTheReason) {
  const auto world = SharedWorld("facility");
  Simulator sim(world, testing::DefaultParams());
  const Vector3d inner = world->LandmarkAt("barrier_inner_max");
  try {
    sim.Spawn({inner.x() + 0.15, 0.0, 0.0});  // inside the 0.3 m east barrier
    ADD_FAILURE() << "a spawn inside the barrier was accepted";
  } catch (const WorldError& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr("the body would start inside 'glass_barrier'"));
  }
  EXPECT_THROW(sim.Spawn({3.5, 170.1, 0.0}), WorldError);  // on a billboard post
  // A metre from the wall, with the body clear of it, is a start.
  const State before = sim.state();
  sim.Spawn({inner.x() - 3.5, 0.0, 0.0});
  EXPECT_NE(Position(sim.state().x).x(), Position(before.x).x());
}

TEST(Spawn, GroundTooUnevenToRestOnIsRefused) {
  // Ground twisted under the car: the left-front and right-rear wheels on 0.7 m pads, the other
  // two on the ground. No plane fits the four within the suspension's 0.29 m of travel.
  const ValidParams vp = testing::DefaultParams();
  const Params& p = vp;
  TriangleMesh m;
  m.name = "twist";
  m.AddQuad(Vector3d(-50, -50, 0), Vector3d(50, -50, 0), Vector3d(50, 50, 0), Vector3d(-50, 50, 0));
  const std::array<Vector3d, 2> pads = {Vector3d(p.b, p.b_l, 0.7), Vector3d(-p.c, -p.b_p, 0.7)};
  for (const Vector3d& c : pads) {
    m.AddQuad(c + Vector3d(-0.5, -0.5, 0), c + Vector3d(0.5, -0.5, 0), c + Vector3d(0.5, 0.5, 0),
              c + Vector3d(-0.5, 0.5, 0));
  }
  const auto world = WorldFromMesh(std::move(m), {-20, 0, 0});
  Simulator sim(std::shared_ptr<const World>(world.get(), [](const World*) {}),
                testing::DefaultParams());
  try {
    sim.Spawn({0.0, 0.0, 0.0});
    ADD_FAILURE() << "a start across a 1.5 m step was accepted";
  } catch (const WorldError& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr("more than the suspension's travel"));
  }
}

// However deep a probe ends up in a wall (a state no spawn allows, reached here by force), the
// contact pushes with at most k_w * kWallPenetrationCap per probe: bounded, never 5e9 N.
TEST(Properties, WallForcesAreBoundedHoweverDeepTheContact) {
  const auto world = SharedWorld("facility");
  const ValidParams p = testing::DefaultParams();
  Simulator sim(world, p);
  const Vector3d inner = world->LandmarkAt("barrier_inner_max");
  const double bound = Params::kNumProbes * p->wall_stiffness * kWallPenetrationCap *
                       (1.0 + p->wall_friction);
  for (double depth : {0.05, 0.5, 1.5}) {
    sim.Spawn({inner.x() - 10.0, 0.0, 0.0});
    State s = sim.state();
    Vector3d pos = Position(s.x);
    pos.x() = inner.x() - p->body_front + depth;  // the front face `depth` into the east wall
    SetPosition(s.x, pos);
    SetVelocity(s.x, Vector3d(20.0, 0.0, 0.0));     // still driving into it
    sim.SetState(s);
    double max_force = 0.0;
    Drive(sim, 2000, {}, [&](const StepRecord& r) {
      max_force = std::max(max_force, r.derived.F_wall_W.norm());
      return false;
    });
    EXPECT_GT(max_force, 0.0) << "no contact at depth " << depth;
    EXPECT_LE(max_force, bound) << "depth " << depth;
    EXPECT_TRUE(sim.state().x.allFinite());
  }
}

// The largest step that resolves the parameters, against the modes' closed forms.
TEST(Params, TheLargestResolvedStepFollowsTheFastestMode) {
  const ValidParams p = testing::PaperParams();
  // The paper car's fastest mode is the wall contact: omega = sqrt(k_w / m), h * omega <= 2.
  const double wall = 2.0 / std::sqrt(p->wall_stiffness / p->mass);
  std::string why;
  EXPECT_NEAR(MaxResolvedStep(p, &why), wall, 1e-12);
  EXPECT_EQ(why, "wall contact");
  EXPECT_EQ(p.max_step(), MaxResolvedStep(p));
  EXPECT_EQ(CheckStep(p, 0.01), "");
  EXPECT_THAT(CheckStep(p, 0.05), ::testing::HasSubstr("wall contact) needs h <= 0.0346"));
  // Stiffer springs on a light car: the heave of a corner sets it, omega = sqrt(k / m_corner).
  const ValidParams light = testing::ParamsWith([](pb::VehicleParams& m) {
    m.set_model(pb::VEHICLE_MODEL_PAPER);
    m.set_mass(300.0);
    m.set_wall_stiffness(1e5);
    for (auto* w : {m.mutable_lf(), m.mutable_rf(), m.mutable_lr(), m.mutable_rr()}) {
      w->set_spring_stiffness(2e6);
      w->set_bump_stop_stiffness(0.0);
    }
  });
  // The rear corners carry less (b < c): theirs is the fastest heave.
  const double m_corner = StaticWheelLoad(light, kLR) / light->gravity;
  EXPECT_NEAR(MaxResolvedStep(light, &why), 1.0 / std::sqrt(2e6 / m_corner), 1e-12) << why;
  EXPECT_EQ(why, "LR spring (heave)");
  EXPECT_THROW(Simulator(SharedWorld("flat"), light, SimConfig{20'000'000}), std::invalid_argument);
}

// The full model's stick-slip elements (docs/model.md 8.6): a wheel on a held brake is a torsional
// spring, omega^2 = (T_cap / theta_b + C_kappa R^2 / sigma_kappa) / J, damped at a rate
// T_cap tau / (theta_b J). The rear wheels hold the most (foot brake and handbrake), so theirs is
// the default car's fastest mode; a step beyond it is refused.
TEST(Params, TheFullModelsHeldBrakeBoundsTheStep) {
  ASSERT_EQ(testing::DefaultParams()->model, VehicleModel::kFull);
  EXPECT_EQ(CheckStep(testing::DefaultParams(), 0.001), "");  // the default car at vdyn's step
  // Longer relaxation lengths than the default's, so that the held brake is the fastest mode
  // (the default's is its tyres' relaxation at speed: the test below).
  const ValidParams def = testing::ParamsWith([](pb::VehicleParams& m) {
    m.set_tire_relaxation_long(0.3);
    m.set_tire_relaxation_lat(0.6);
  });
  auto held = [](const ValidParams& p, double* damping_rate) {
    const WheelParams& wp = p->wheel[kLR];
    // A rear wheel: the foot brake's (1 - front fraction) share of brake_force_max and the
    // handbrake's, half each per wheel, at radius R.
    const double T_cap = 0.5 * p->brake_force_max * (1.0 - p->brake_front_fraction) * wp.radius +
                         0.5 * p->handbrake_force_max * wp.radius;
    const double k_brake = T_cap / p->brake_stick_angle;
    *damping_rate = k_brake * p->stick_damping_time / wp.spin_inertia;
    const double k = k_brake + wp.longitudinal_stiffness * wp.radius * wp.radius /
                                   p->tire_relaxation_long;
    return std::sqrt(k / wp.spin_inertia);
  };
  double rate = 0;
  std::string why;
  EXPECT_NEAR(MaxResolvedStep(def, &why), 2.0 / held(def, &rate), 1e-12) << why;
  EXPECT_EQ(why, "LR wheel on a held brake");
  EXPECT_THAT(CheckStep(def, 0.006), ::testing::HasSubstr("LR wheel on a held brake"));
  EXPECT_THROW(Simulator(SharedWorld("flat"), def, SimConfig{6'000'000}), std::invalid_argument);
  // A light wheel: the stick damping's real pole comes first (RK4: h * rate <= 2.5).
  const ValidParams light = testing::ParamsWith([](pb::VehicleParams& m) {
    for (auto* w : {m.mutable_lf(), m.mutable_rf(), m.mutable_lr(), m.mutable_rr()}) {
      w->set_spin_inertia(0.02);
    }
  });
  held(light, &rate);
  EXPECT_NEAR(MaxResolvedStep(light, &why), 2.5 / rate, 1e-12) << why;
  EXPECT_EQ(why, "LR brake stick damping");
  EXPECT_THROW(Simulator(SharedWorld("flat"), light, SimConfig{1'000'000}), std::invalid_argument);
}

// The contact patch's relaxation (docs/model.md 8.2) is a real pole at -|v| / sigma; RK4 is stable
// on the negative real axis to h lambda = 2.785, and a vehicle may be spawned at 110 m/s. A short
// lateral relaxation length was accepted and the state went non-finite in a drive at 50 km/h
// (sigma 3 mm: h lambda = 4.6); now it is refused for the step, naming the mode.
TEST(Params, TheTyresRelaxationAtTheFastestSpawnSpeedBoundsTheStep) {
  const ValidParams def = testing::DefaultParams();
  std::string why;
  EXPECT_NEAR(MaxResolvedStep(def, &why), 2.78 * def->tire_relaxation_long / 110.0, 1e-12) << why;
  EXPECT_EQ(why, "LF tyre relaxation, longitudinal, at 110 m/s");
  const ValidParams short_lat = testing::ParamsWith(
      [](pb::VehicleParams& m) { m.set_tire_relaxation_lat(0.003); });
  EXPECT_NEAR(MaxResolvedStep(short_lat, &why), 2.78 * 0.003 / 110.0, 1e-15) << why;
  EXPECT_EQ(why, "LF tyre relaxation, lateral, at 110 m/s");
  EXPECT_THAT(CheckStep(short_lat, 0.001),
              ::testing::HasSubstr("(LF tyre relaxation, lateral, at 110 m/s) needs h <= 7.58e-5"));
  EXPECT_THROW(Simulator(SharedWorld("flat"), short_lat, SimConfig{1'000'000}),
               std::invalid_argument);
  // At the bound the pole is inside RK4's region: a 110 m/s car keeps a finite state at h = 1 ms
  // with the shortest length that step resolves, 0.0396 m (h lambda = 2.78), driving straight.
  const double sigma = 110.0 * 0.001 / 2.78 + 1e-6;
  const ValidParams at_bound = testing::ParamsWith([sigma](pb::VehicleParams& m) {
    m.set_tire_relaxation_lat(sigma);
    m.set_tire_relaxation_long(sigma);
  });
  Simulator sim(SharedWorld("flat"), at_bound, SimConfig{1'000'000});
  sim.Spawn({0.0, 0.0, 0.0}, 100.0);
  for (int k = 0; k < 2000; ++k) ASSERT_EQ(sim.Step(), StepStatus::kOk) << "step " << k;
  EXPECT_TRUE(sim.state().x.allFinite());
}

}  // namespace
}  // namespace vdyn
