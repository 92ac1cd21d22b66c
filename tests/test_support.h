// Shared helpers for the tests: worlds, vehicles, drives and scratch folders.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "vdyn/bridge/params.h"
#include "vdyn/physics/simulator.h"
#include "vdyn/physics/world.h"

// VDYN_TEST_ASAN: this build runs under AddressSanitizer (GCC names it with a macro, clang with
// a feature).
#if defined(__SANITIZE_ADDRESS__)
#define VDYN_TEST_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define VDYN_TEST_ASAN 1
#endif
#endif

namespace vdyn::testing {

// Whether this build runs under the sanitizers. The long drives of the release suite run a tenth
// as long there: the sanitizers see the same code paths in one minute as in ten, and the
// sanitizer build runs them 20-30 times slower.
#if defined(VDYN_TEST_ASAN)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif

// While alive, warnings and errors logged are expected (and counted), not failures.
class ExpectLogs {
 public:
  ExpectLogs();
  ~ExpectLogs();
  int count() const;

 private:
  int before_;
};

// A fresh scratch folder per test, removed at the end.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

void WriteFile(const std::filesystem::path& path, const std::string& text);
std::string ReadFile(const std::filesystem::path& path);

// Built-in worlds are built once per test binary and shared (they are immutable after Commit).
std::shared_ptr<const World> SharedWorld(const std::string& name);

// A plane z = slope * x over a large square, as one mesh.
TriangleMesh InclinedPlane(double slope, double half_size);

ValidParams DefaultParams();
// The defaults with `edit` applied to the message first.
ValidParams ParamsWith(const std::function<void(pb::VehicleParams&)>& edit);
// The defaults with the paper's model (VEHICLE_MODEL_PAPER), then `edit`.
ValidParams PaperParams();
ValidParams PaperParamsWith(const std::function<void(pb::VehicleParams&)>& edit);

// The closed-form top speed, m/s: where the top gear's drive force at full load, eta i T(i v / R)
// / R with T the torque of P = P_max (r + r^2 - r^3) (r: engine speed over that of P_max), meets
// aerodynamic drag 1/2 rho cx Sx v^2 plus `rolling_N(v)` (bisection between 20 and 120 m/s).
double ClosedFormTopSpeed(const Params& p, const std::function<double(double)>& rolling_N);

// Steps until `stop` returns true or `max_steps` is reached; returns the steps taken. Fails the
// test if a step is non-finite.
std::int64_t Drive(Simulator& sim, std::int64_t max_steps,
                   const std::function<void(Simulator&)>& before_step,
                   const std::function<bool(const StepRecord&)>& after_step = {});

}  // namespace vdyn::testing
