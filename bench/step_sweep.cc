// Step-size sweep: the largest fixed step h at which the model stays stable.
//
// Three drives at each h - the demo drive on `facility` (bumps, washboard, jump, step steer,
// full stop), two minutes of the rough-terrain circuit (CircuitDriver), and a head-on impact on
// the glass barrier at 50 km/h - compared with the same drives at h = 1 ms. A step size is
// stable when every drive stays finite and
//  - demo, rough: the largest spring force and body rate stay within 1.5x of the 1 ms run's, the
//    vertical-acceleration RMS (the paper's "vibration") within 1.25x, and the braked car at the
//    end of the demo stands still (speed below 1 cm/s);
//  - barrier: no point of the body passes the barrier's far face, the car never moves faster
//    than 5 % above the 50 km/h it came at (no energy gained in the impact), the deepest
//    penetration stays within 1.5x and the impact turns the body no faster than 1 rad/s
//    (0.11 rad/s at 1 ms: a resolved impact stays gentle).
// The largest stable step is reported per drive and for all three together.
//
// Usage: step_sweep [--model paper|full] [h_ms ...]   (default: the full model; a list of steps
// from 1 to 25 ms, 1/90 s included)
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "vdyn/physics/drivers.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/bridge/params.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/physics/world.h"

namespace {

using vdyn::DriverInput;
using vdyn::Simulator;

struct Metrics {
  bool finite = true;
  double max_Fp = 0;      // N
  double max_rate = 0;    // rad/s
  double az_rms = 0;      // m/s^2, body-Z acceleration
  double end_error = 0;   // m, final position vs the 1 ms run
  double end_speed = 0;   // m/s
  double max_speed = 0;   // m/s
  double max_pen = 0;     // m, deepest wall penetration
  double max_body_y = -1e300;  // m, northmost body point (barrier drive)
  Eigen::Vector3d end = Eigen::Vector3d::Zero();
};

enum class Drive { kDemo, kRough, kBarrier };
const char* kDriveNames[] = {"demo", "rough", "barrier"};

Metrics Run(const std::shared_ptr<const vdyn::World>& world, const vdyn::ValidParams& params,
            Drive drive, std::int64_t step_ns) {
  vdyn::SimConfig cfg;
  cfg.step_ns = step_ns;
  cfg.check_step = false;  // the sweep looks for the real limit, past CheckStep's bound
  Simulator sim(world, params, cfg);
  const vdyn::Maneuver demo = vdyn::Maneuver::Parse(vdyn::DemoManeuverCsv(), "demo");
  vdyn::CircuitDriver circuit;
  double seconds = 0;
  switch (drive) {
    case Drive::kDemo:
      seconds = demo.end_time();
      break;
    case Drive::kRough: {
      const Eigen::Vector3d c = world->LandmarkAt("rough_terrain_center");
      circuit.center = c.head<2>();
      sim.Spawn({c.x() + circuit.radius, c.y(), std::numbers::pi / 2});
      seconds = 120.0;
      break;
    }
    case Drive::kBarrier: {
      const Eigen::Vector3d inner = world->LandmarkAt("barrier_inner_max");
      sim.Spawn({100.0, inner.y() - 20.0, std::numbers::pi / 2}, 50.0 / 3.6);
      seconds = 4.0;
      break;
    }
  }
  Metrics m;
  const auto n = static_cast<std::int64_t>(std::llround(seconds / sim.h()));
  double az2 = 0;
  for (std::int64_t i = 0; i < n; ++i) {
    DriverInput in;
    if (drive == Drive::kDemo) in = vdyn::FromManeuver(demo.At(sim.time()));
    if (drive == Drive::kRough) in = circuit.Input(sim.state(), sim.time());
    if (drive == Drive::kBarrier) {
      in.cruise_on = true;
      in.cruise_speed = 50.0 / 3.6;
    }
    sim.SetInput(in);
    if (sim.Step() != vdyn::StepStatus::kOk) {
      m.finite = false;
      break;
    }
    const vdyn::StepRecord& r = sim.last_step();
    for (const auto& w : r.derived.wheel) m.max_Fp = std::max(m.max_Fp, w.Fp);
    m.max_rate = std::max(m.max_rate, vdyn::AngularVelocityB(sim.state().x).norm());
    const Eigen::Matrix3d R = vdyn::Orientation(r.state.x).toRotationMatrix();
    const double az = (R.transpose() * r.derived.a_WT_W).z();
    az2 += az * az;
    m.max_pen = std::max(m.max_pen, r.derived.wall_penetration_max);
    m.max_speed = std::max(m.max_speed, vdyn::Velocity(sim.state().x).norm());
    for (int k = 0; k < vdyn::Params::kNumProbes; ++k) {
      const Eigen::Vector3d corner =
          vdyn::Position(r.state.x) +
          R * (params->p_TO_B + params->probe_length[k] * params->probe_dir_B[k]);
      m.max_body_y = std::max(m.max_body_y, corner.y());
    }
  }
  m.az_rms = std::sqrt(az2 / static_cast<double>(std::max<std::int64_t>(n, 1)));
  m.end = vdyn::Position(sim.state().x);
  m.end_speed = vdyn::Velocity(sim.state().x).norm();
  return m;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<double> steps_ms;
  vdyn::pb::VehicleParams msg = vdyn::DefaultVehicleParams();
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--model" && i + 1 < argc) {
      const std::string m = argv[++i];
      if (m != "paper" && m != "full") {
        std::fprintf(stderr, "usage: step_sweep [--model paper|full] [h_ms ...]\n");
        return 2;
      }
      msg.set_model(m == "paper" ? vdyn::pb::VEHICLE_MODEL_PAPER : vdyn::pb::VEHICLE_MODEL_FULL);
      continue;
    }
    steps_ms.push_back(std::atof(argv[i]));
  }
  if (steps_ms.empty()) {
    steps_ms = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 1000.0 / 120.0, 1000.0 / 90.0, 12.5, 15, 20, 25};
    std::sort(steps_ms.begin(), steps_ms.end());
  }
  std::shared_ptr<const vdyn::World> world = vdyn::BuildBuiltinWorld("facility");
  const vdyn::ValidParams params = vdyn::ParamsFromProto(msg);
  std::printf("model: %s\n", msg.model() == vdyn::pb::VEHICLE_MODEL_PAPER ? "paper" : "full");

  Metrics ref[3];
  for (int d = 0; d < 3; ++d) ref[d] = Run(world, params, static_cast<Drive>(d), 1'000'000);
  const double far_face =
      world->LandmarkAt("barrier_inner_max").y() + world->LandmarkAt("barrier_thickness").y();

  std::printf("%8s %8s %7s %10s %8s %8s %10s %9s %8s  %s\n", "h_ms", "drive", "finite",
              "max_Fp_kN", "max_w", "az_rms", "end_err_m", "end_v_mps", "pen_m", "verdict");
  double largest[4] = {0, 0, 0, 0};  // per drive, then all together
  bool unbroken[4] = {true, true, true, true};
  for (const double h_ms : steps_ms) {
    const auto step_ns = static_cast<std::int64_t>(std::llround(h_ms * 1e6));
    bool all = true;
    for (int d = 0; d < 3; ++d) {
      Metrics m = Run(world, params, static_cast<Drive>(d), step_ns);
      m.end_error = (m.end - ref[d].end).norm();
      bool ok = m.finite;
      if (static_cast<Drive>(d) == Drive::kBarrier) {
        ok = ok && m.max_body_y < far_face && m.max_speed <= 1.05 * 50.0 / 3.6 &&
             m.max_pen <= 1.5 * ref[d].max_pen && m.max_rate <= 1.0;
      } else {
        ok = ok && m.max_Fp <= 1.5 * ref[d].max_Fp && m.max_rate <= 1.5 * ref[d].max_rate &&
             m.az_rms <= 1.25 * ref[d].az_rms;
        if (static_cast<Drive>(d) == Drive::kDemo) ok = ok && m.end_speed < 0.01;
      }
      all = all && ok;
      unbroken[d] = unbroken[d] && ok;
      if (unbroken[d]) largest[d] = h_ms;
      std::printf("%8.3f %8s %7s %10.2f %8.3f %8.3f %10.3f %9.4f %8.3f  %s\n", h_ms,
                  kDriveNames[d], m.finite ? "yes" : "NO", m.max_Fp / 1000.0, m.max_rate, m.az_rms,
                  m.end_error, m.end_speed, m.max_pen, ok ? "stable" : "UNSTABLE");
    }
    unbroken[3] = unbroken[3] && all;
    if (unbroken[3]) largest[3] = h_ms;
  }
  std::printf("largest stable step (it and every smaller step listed stable):\n");
  for (int d = 0; d < 3; ++d) std::printf("  %-8s %.3f ms\n", kDriveNames[d], largest[d]);
  std::printf("  %-8s %.3f ms\n", "all", largest[3]);
  std::string mode;
  const double bound_s = vdyn::MaxResolvedStep(params.get(), &mode);
  std::printf("the parameters' largest resolved step (CheckStep, server refuses beyond): %.3f ms (%s)\n",
              bound_s * 1e3, mode.c_str());
  return 0;
}
