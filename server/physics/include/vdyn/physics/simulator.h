// Simulator: one vehicle on one world, stepped by RK4 at a fixed step h.
//
// Data kinds kept apart (docs/architecture.md):
//   parameters  ValidParams   - validated, replaced only between steps (SetParams)
//   state       State         - exactly what is integrated and hashed
//   workspace   Workspace     - preallocated scratch; a step allocates nothing
// A step reads as its stages: latch input -> controls -> find walls -> RK4 (sense terrain,
// forces, derivatives at each of 4 stages) -> post-step (normalise, checks, record).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "vdyn/physics/controls.h"
#include "vdyn/physics/full_model.h"
#include "vdyn/physics/params.h"
#include "vdyn/physics/rk4.h"
#include "vdyn/physics/state.h"
#include "vdyn/physics/vehicle_model.h"
#include "vdyn/physics/world.h"

namespace vdyn {

struct SimConfig {
  std::int64_t step_ns = 1'000'000;  // h = 1 ms
  // Refuse parameters the step cannot resolve (CheckStep). Only bench/step_sweep turns this off,
  // to find where RK4 really goes unstable beyond the bound.
  bool check_step = true;
};

// What one step saw and did, reported at its start time t_n = step * h: the state x_n, the input
// latched at t_n and the controls applied over [t_n, t_n + h], and every derived quantity at x_n.
struct StepRecord {
  std::int64_t step = 0;
  double t = 0;  // s
  State state;
  DriverInput input;
  AppliedControl control;
  Derived derived;
  std::uint64_t hash_after = 0;  // StateHash of x_{n+1}
};

// kNonFinite: the step made the state non-finite. kUnderGround: no wheel touches the ground and
// the body's centre is under all of it (nothing below it, the surface above it): this model has
// no contact of the body with the ground, so a car that rolled over falls through it for ever.
// Either way the state stays at x_n (the step is discarded) and the caller decides what follows
// (the session puts the vehicle back on its wheels there, a batch stops with the reason).
// kRunaway: the new state is finite but faster than any vehicle (kRunawaySpeedMps) or spinning
// faster than any (kRunawayRateRadps): parameters changed past what the model resolves (a spring
// made 1000 times stiffer while compressed, a tyre's nominal load of a nanonewton) blow up over a
// few steps, and each state on the way was published and kept (one car ended 1e47 m away).
enum class StepStatus { kOk, kNonFinite, kUnderGround, kRunaway };
inline constexpr double kRunawaySpeedMps = 1000.0;
inline constexpr double kRunawayRateRadps = 1000.0;
// What happened in a discarded step, for a person: "its state became non-finite", "it fell
// through the ground (...)", "its state ran away (faster than 1000 m/s or ...)"; empty for kOk.
// The one text of each status: the session's log and replies, a batch's error and a
// re-simulation's add only what they did about it.
const char* StepStatusText(StepStatus status);

class Simulator {
 public:
  // Starts at rest at the world's spawn pose (throws WorldError when it cannot start there).
  // Both constructors throw std::invalid_argument when the parameters do not resolve at the step.
  Simulator(std::shared_ptr<const World> world, const ValidParams& params, SimConfig config = {});
  // Starts from `initial` as it is (a recorded state, or one Spawn() replaces at once).
  Simulator(std::shared_ptr<const World> world, const ValidParams& params, SimConfig config,
            const State& initial);

  // Takes effect at the next step boundary. A change of model converts the state to the new
  // model's layout (ConvertState). Throws std::invalid_argument when the parameters do not
  // resolve at this simulator's step (CheckStep; the edge checks it first, with a reason).
  void SetParams(const ValidParams& params);
  // Latched at the next step boundary. Non-finite or out-of-range values are clamped and counted.
  void SetInput(const DriverInput& input);
  // Places the vehicle at rest (or moving at `speed` along its heading) in static equilibrium on
  // the terrain below (x, y). Throws WorldError, with the reason, when there is no terrain below,
  // when the body would start inside a wall or any other surface, or when the ground under the
  // wheels is too uneven to rest on (SpawnObstruction).
  void Spawn(const Pose2& pose, double speed = 0.0);
  // The state as given, converted to the parameters' model if it is in the other's layout.
  void SetState(const State& state);

  // Advances by h. A step whose result is not finite is contained: the state stays at x_n, the
  // count is raised and kNonFinite is returned.
  [[nodiscard]] StepStatus Step();

  // Derived quantities (and the controls) at the current state with the current input; nothing
  // advances.
  void Forward(Derived& out, AppliedControl* control = nullptr) const;

  const Params& params() const { return params_.get(); }
  const ValidParams& valid_params() const { return params_; }
  const State& state() const { return state_; }
  const DriverInput& input() const { return input_; }
  const StepRecord& last_step() const { return record_; }
  const World& world() const { return *world_; }
  double h() const { return h_; }
  double time() const { return static_cast<double>(state_.step) * h_; }
  std::int64_t step_ns() const { return config_.step_ns; }
  std::uint64_t nonfinite_steps() const { return nonfinite_steps_; }
  std::uint64_t under_ground_steps() const { return under_ground_steps_; }
  std::uint64_t runaway_steps() const { return runaway_steps_; }
  std::uint64_t sanitized_inputs() const { return sanitized_inputs_; }
  // Steps whose horizontal (wall) traces were cast: near a steep surface.
  std::uint64_t wall_traced_steps() const { return wall_traced_steps_; }
  // Steps that broke an always-on invariant (CheckStepDemands), and the last one's reason ("" when
  // none): counted in every build, reported in the server's diagnostics.
  std::uint64_t invariant_failures() const { return invariant_failures_; }
  const char* last_invariant_failure() const { return last_invariant_failure_; }

 private:
  struct Workspace {
    Rk4Workspace rk4;
    WallPlanes walls;
    WheelEdges edges;
    Derived stage_derived;
    State start;
  };

  std::shared_ptr<const World> world_;
  ValidParams params_;
  SimConfig config_;
  double h_;
  State state_;
  DriverInput input_;
  StepRecord record_;
  Workspace ws_;
  std::uint64_t nonfinite_steps_ = 0;
  std::uint64_t under_ground_steps_ = 0;
  std::uint64_t runaway_steps_ = 0;
  std::uint64_t sanitized_inputs_ = 0;
  std::uint64_t wall_traced_steps_ = 0;
  std::uint64_t invariant_failures_ = 0;
  char last_invariant_failure_[160] = "";
};

// The invariants that must hold in every build (Drake's DRAKE_DEMAND tier), checked after every
// step without allocating: the state the step starts from is finite with a unit quaternion, the
// new state's quaternion is a unit one, and every spring force is >= 0. Returns true when they
// hold; otherwise writes which failed, with its value, into why[0..n) (NUL-terminated).
bool CheckStepDemands(const StepRecord& r, const State& after, char* why, std::size_t n);

// Invariants of a step the model guarantees by construction, checked after every step in debug and
// sanitizer builds (VDYN_CHECK_INVARIANTS; compiled out elsewhere): the state it starts from and
// the one it ends at have a unit quaternion (the step normalises it), every derived quantity
// reported is a finite number (a non-finite result is contained before: the step is discarded),
// and every spring force is >= 0 (a spring pushes, it never pulls). Empty when they hold, else
// which one failed and with what value.
std::string CheckStepInvariants(const StepRecord& r, const State& after);
// Called with the failure when an invariant check fails. The physics cannot log: the default
// handler is the C library's assertion failure (message on stderr, abort); tests install their own.
using InvariantHandler = void (*)(const std::string& what);
void SetInvariantHandler(InvariantHandler handler);
// Whether this build checks invariants after every step.
constexpr bool kCheckInvariants =
#ifdef VDYN_CHECK_INVARIANTS
    true;
#else
    false;
#endif

// Static equilibrium at (x, y, yaw) on the terrain: level in yaw, height, pitch and roll fitted so
// that each spring carries its static share of the weight. Throws WorldError without terrain.
// `max_misfit` (if given) gets the largest distance, m, between a wheel's ground and the plane the
// four wheels were fitted to (0 on even ground).
State RestingState(const Params& p, const Terrain& terrain, const Pose2& pose, double speed,
                   double* max_misfit = nullptr);

// Why a vehicle cannot start in state s (empty when it can): a horizontal trace from the body's
// centre meets a surface inside the body box (the vehicle would start inside a wall, a ramp, a
// building), or the ground under the wheels departs from one plane by more than the suspension's
// travel (`max_misfit` from RestingState).
std::string SpawnObstruction(const Params& p, const Terrain& terrain, const State& s,
                             double max_misfit);

}  // namespace vdyn
