#include "test_support.h"

#include <fstream>
#include <map>
#include <mutex>
#include <numbers>
#include <random>
#include <sstream>

#include <gtest/gtest.h>
#include <unistd.h>

namespace vdyn::testing {

TempDir::TempDir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = info != nullptr ? std::string(info->test_suite_name()) + "." + info->name()
                                     : std::string("vdyn");
  for (char& c : name) {
    if (c == '/') c = '_';
  }
  path_ = std::filesystem::temp_directory_path() /
          ("vdyn-test-" + std::to_string(::getpid()) + "-" + name);
  std::filesystem::remove_all(path_);
  std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

void WriteFile(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
  ASSERT_TRUE(out.good()) << "cannot write " << path;
}

std::string ReadFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::shared_ptr<const World> SharedWorld(const std::string& name) {
  static std::mutex mu;
  static std::map<std::string, std::shared_ptr<const World>> cache;
  std::lock_guard<std::mutex> lock(mu);
  auto& w = cache[name];
  if (!w) w = BuildBuiltinWorld(name);
  return w;
}

TriangleMesh InclinedPlane(double slope, double half_size) {
  TriangleMesh m;
  m.name = "incline";
  const double s = half_size;
  m.AddQuad(Eigen::Vector3d(-s, -s, -slope * s), Eigen::Vector3d(s, -s, slope * s),
            Eigen::Vector3d(s, s, slope * s), Eigen::Vector3d(-s, s, -slope * s));
  return m;
}

ValidParams DefaultParams() { return ParamsFromProto(DefaultVehicleParams()); }

ValidParams ParamsWith(const std::function<void(pb::VehicleParams&)>& edit) {
  pb::VehicleParams msg = DefaultVehicleParams();
  edit(msg);
  return ParamsFromProto(msg);
}

ValidParams PaperParams() { return PaperParamsWith([](pb::VehicleParams&) {}); }

ValidParams PaperParamsWith(const std::function<void(pb::VehicleParams&)>& edit) {
  pb::VehicleParams msg = DefaultVehicleParams();
  msg.set_model(pb::VEHICLE_MODEL_PAPER);
  edit(msg);
  return ParamsFromProto(msg);
}

double ClosedFormTopSpeed(const Params& p, const std::function<double(double)>& rolling_N) {
  const double R = p.wheel[kLF].radius;
  const double i_top = p.gear_ratio_top * p.final_drive_ratio;
  const double w_p = p.engine_rpm_power_max * 2.0 * std::numbers::pi / 60.0;
  auto excess = [&](double speed) {
    const double r = i_top * speed / R / w_p;
    const double T = p.engine_power_max / w_p * (1.0 + r - r * r);
    return p.drivetrain_efficiency * i_top * T / R - 0.5 * p.rho * p.cx * p.sx * speed * speed -
           rolling_N(speed);
  };
  double lo = 20.0, hi = 120.0;
  for (int i = 0; i < 100; ++i) {
    const double mid = 0.5 * (lo + hi);
    (excess(mid) > 0.0 ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

std::int64_t Drive(Simulator& sim, std::int64_t max_steps,
                   const std::function<void(Simulator&)>& before_step,
                   const std::function<bool(const StepRecord&)>& after_step) {
  for (std::int64_t i = 0; i < max_steps; ++i) {
    if (before_step) before_step(sim);
    if (sim.Step() != StepStatus::kOk) {
      ADD_FAILURE() << "non-finite state at t = " << sim.time();
      return i;
    }
    if (after_step && after_step(sim.last_step())) return i + 1;
  }
  return max_steps;
}

}  // namespace vdyn::testing
