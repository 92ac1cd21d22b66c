#include "vdyn/physics/simulator.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include <Eigen/Dense>

#include "vdyn/base/text.h"
#include "vdyn/physics/full_model.h"

namespace vdyn {

namespace {

// The horizontal traces held for a step, at x: the walls (both models) and the kerb edges (the
// full model). Returns whether the wall traces were cast (near a steep surface).
bool FindHeldContacts(const Params& p, const Terrain& terrain, const StateVector& x,
                      WallPlanes& walls, WheelEdges& edges) {
  const bool traced = FindWalls(p, terrain, x, walls);
  if (p.model == VehicleModel::kFull) FindWheelEdges(p, terrain, x, edges);
  return traced;
}

// xdot = f(x) of the parameters' model, with the controls and the held contacts: the one place
// the paper's and the full model's equations are chosen, shared by Step and Forward (as MuJoCo's
// mj_forward serves mj_step).
void EvaluateModel(const Params& p, const Terrain& terrain, const AppliedControl& u,
                   const WallPlanes& walls, const WheelEdges& edges, const StateVector& x,
                   StateVector& xdot, Derived& out, bool report_all) {
  if (p.model == VehicleModel::kFull) {
    EvaluateDerivativeFull(p, terrain, u, walls, edges, x, xdot, out, report_all);
  } else {
    EvaluateDerivative(p, terrain, u, walls, x, xdot, out, report_all);
  }
}

}  // namespace

State RestingState(const Params& p, const Terrain& terrain, const Pose2& pose, double speed,
                   double* max_misfit) {
  const Eigen::Matrix3d R_yaw =
      Eigen::AngleAxisd(pose.yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const double top = terrain.above_all_z();
  // Linearised mount height: z_T - x theta + y phi + (R p_TA)_z = required height, solved for
  // (z_T, theta, phi) in the least-squares sense (pitch theta nose down, roll phi right down).
  Eigen::Matrix<double, 4, 3> A;
  Eigen::Vector4d rhs;
  for (int w = 0; w < kNumWheels; ++w) {
    const WheelParams& wp = p.wheel[w];
    const Eigen::Vector3d a_W = R_yaw * p.p_TA_B[w];
    const Eigen::Vector3d origin(pose.x + a_W.x(), pose.y + a_W.y(), top);
    const TraceHit hit = terrain.GroundBelow(origin.x(), origin.y());
    if (!hit.hit) {
      throw WorldError("no terrain below wheel " + std::string(kWheelNames[w]) + " at (" +
                       base::FormatApprox(origin.x(), 6) + ", " + base::FormatApprox(origin.y(), 6) +
                       ")");
    }
    const double ground_z = top - hit.distance;
    // Spring deformation carrying the static load (with the bump stop if it reaches it).
    const double F = StaticWheelLoad(p, w);
    double lT = F / wp.spring_stiffness;
    if (wp.free_length - lT < wp.bump_stop_length) {
      lT = (F + wp.bump_stop_stiffness * (wp.free_length - wp.bump_stop_length)) /
           (wp.spring_stiffness + wp.bump_stop_stiffness);
    }
    double lS = wp.free_length - lT;
    if (p.model == VehicleModel::kFull) {
      // The full model's wheel hangs on its spring (within its travel) and its tire is
      // compressed by the load.
      lS = std::clamp(lS, wp.min_length, wp.max_length) - F / p.full.tire_vertical_stiffness[w];
    }
    A(w, 0) = 1.0;
    A(w, 1) = -p.p_TA_B[w].x();
    A(w, 2) = p.p_TA_B[w].y();
    rhs[w] = ground_z + wp.radius + lS + wp.z_offset;
  }
  const Eigen::Vector3d sol = A.colPivHouseholderQr().solve(rhs);
  if (max_misfit != nullptr) *max_misfit = (A * sol - rhs).cwiseAbs().maxCoeff();
  State s;
  SetPosition(s.x, Eigen::Vector3d(pose.x, pose.y, sol[0]));
  SetOrientation(s.x, QuaternionFromRollPitchYaw(sol[2], sol[1], pose.yaw));
  SetVelocity(s.x, speed * (R_yaw * Eigen::Vector3d::UnitX()));
  SetAngularVelocityB(s.x, Eigen::Vector3d::Zero());
  return p.model == VehicleModel::kFull ? InitFullState(p, s) : s;
}

Simulator::Simulator(std::shared_ptr<const World> world, const ValidParams& params,
                     SimConfig config)
    : world_(std::move(world)),
      params_(params),
      config_(config),
      h_(static_cast<double>(config.step_ns) * 1e-9) {
  if (const std::string why = config_.check_step ? CheckStep(params_, h_) : std::string();
      !why.empty()) {
    throw std::invalid_argument(why);
  }
  Spawn(world_->spawn);
}

Simulator::Simulator(std::shared_ptr<const World> world, const ValidParams& params,
                     SimConfig config, const State& initial)
    : world_(std::move(world)),
      params_(params),
      config_(config),
      h_(static_cast<double>(config.step_ns) * 1e-9),
      state_(ConvertState(params, initial)) {
  if (const std::string why = config_.check_step ? CheckStep(params_, h_) : std::string();
      !why.empty()) {
    throw std::invalid_argument(why);
  }
}

void Simulator::SetParams(const ValidParams& params) {
  if (const std::string why = config_.check_step ? CheckStep(params, h_) : std::string();
      !why.empty()) {
    throw std::invalid_argument(why);
  }
  params_ = params;
  state_ = ConvertState(params_, state_);
}

void Simulator::SetState(const State& state) { state_ = ConvertState(params_, state); }

void Simulator::SetInput(const DriverInput& input) {
  input_ = input;
  if (!SanitizeInput(input_)) ++sanitized_inputs_;
}

std::string SpawnObstruction(const Params& p, const Terrain& terrain, const State& s,
                             double max_misfit) {
  const Eigen::Matrix3d R_WB = Orientation(s.x).normalized().toRotationMatrix();
  const Eigen::Vector3d p_WO = Position(s.x) + R_WB * p.p_TO_B;
  for (int k = 0; k < Params::kNumProbes; ++k) {
    const TraceHit hit = terrain.Trace(p_WO, R_WB * p.probe_dir_B[k], p.probe_length[k]);
    if (hit.hit) {
      const std::string& mesh = terrain.meshes()[hit.mesh].name;
      char where[96];
      std::snprintf(where, sizeof where, "%.2f m from its centre, %.2f m inside the body",
                    hit.distance, p.probe_length[k] - hit.distance);
      return "the body would start inside '" + mesh + "' (" + where + ")";
    }
  }
  // The wheels rest on one plane within the suspension's travel.
  double travel = 1e300;
  for (const WheelParams& wp : p.wheel) travel = std::min(travel, wp.free_length - wp.bump_stop_length);
  if (max_misfit > travel) {
    char why[160];
    std::snprintf(why, sizeof why,
                  "the ground under the wheels departs from one plane by %.2f m, more than the "
                  "suspension's travel (%.2f m): no place to rest",
                  max_misfit, travel);
    return why;
  }
  return {};
}

void Simulator::Spawn(const Pose2& pose, double speed) {
  double misfit = 0.0;
  const State s = RestingState(params_.get(), world_->terrain, pose, speed, &misfit);
  const std::string obstruction = SpawnObstruction(params_.get(), world_->terrain, s, misfit);
  if (!obstruction.empty()) throw WorldError(obstruction);
  state_ = s;
}

// The C library's assertion failure (glibc): the message on stderr, then abort. Declared here as
// <cassert> declares it only without NDEBUG, and the invariants are also checked in builds with it.
extern "C" [[noreturn]] void __assert_fail(const char* assertion, const char* file,
                                           unsigned int line, const char* function) noexcept;

namespace {

void AssertionFailure(const std::string& what) {
  __assert_fail(what.c_str(), __FILE__, __LINE__, "vdyn::Simulator::Step");
}

std::atomic<InvariantHandler> g_invariant_handler{&AssertionFailure};

void InvariantFailed(const std::string& what) {
  g_invariant_handler.load()(what);
}

// Sets `why` to "wheel name = value is not a finite number" when v is not finite (and `why` is
// still empty). Nothing is allocated unless it fails: the check runs every step.
void Finite(std::string& why, const char* wheel, const char* name, double v) {
  if (std::isfinite(v) || !why.empty()) return;
  char buf[96];
  std::snprintf(buf, sizeof buf, "%s%s%s = %g is not a finite number", wheel, *wheel ? " " : "",
                name, v);
  why = buf;
}
void Finite(std::string& why, const char* wheel, const char* name, const Eigen::Vector3d& v) {
  for (int i = 0; i < 3; ++i) Finite(why, wheel, name, v[i]);
}

std::string UnitQuaternion(const char* which, const State& s) {
  if (!s.x.allFinite()) return {};  // a non-finite state is contained, not an invariant
  const double n = s.x.segment<4>(sx::kQ).norm();
  if (std::abs(n - 1.0) <= 1e-9) return {};
  char buf[128];
  std::snprintf(buf, sizeof buf, "the %s state's quaternion has norm %.9g, not 1", which, n);
  return buf;
}

}  // namespace

void SetInvariantHandler(InvariantHandler handler) {
  g_invariant_handler.store(handler != nullptr ? handler : &AssertionFailure);
}

bool CheckStepDemands(const StepRecord& r, const State& after, char* why, std::size_t n) {
  constexpr double kUnitTolerance = 1e-9;
  if (!r.state.x.allFinite()) {
    std::snprintf(why, n, "demand: the starting state is not finite");
    return false;
  }
  const State* states[] = {&r.state, &after};
  const char* names[] = {"starting", "new"};
  for (int i = 0; i < 2; ++i) {
    const double q = states[i]->x.segment<4>(sx::kQ).norm();
    if (!(std::abs(q - 1.0) <= kUnitTolerance)) {
      std::snprintf(why, n, "demand: the %s state's quaternion has norm %.9g, not 1", names[i], q);
      return false;
    }
  }
  for (int w = 0; w < kNumWheels; ++w) {
    const double Fp = r.derived.wheel[w].Fp;
    if (!(Fp >= 0.0)) {
      std::snprintf(why, n, "demand: wheel %s: spring force Fp = %g N, not >= 0",
                    kWheelNames[static_cast<std::size_t>(w)].data(), Fp);
      return false;
    }
  }
  return true;
}

std::string CheckStepInvariants(const StepRecord& r, const State& after) {
  std::string why = UnitQuaternion("starting", r.state);
  if (why.empty()) why = UnitQuaternion("new", after);
  if (!why.empty()) return "invariant: " + why;
  const Derived& d = r.derived;
  for (int w = 0; w < kNumWheels && why.empty(); ++w) {
    const WheelOutputs& o = d.wheel[w];
    const char* wheel = kWheelNames[static_cast<std::size_t>(w)].data();
    if (o.Fp < 0.0) {
      char buf[128];
      std::snprintf(buf, sizeof buf, "wheel %s: spring force Fp = %g N < 0 (a spring only pushes)",
                    wheel, o.Fp);
      why = buf;
    }
    const std::pair<const char*, double> scalars[] = {{"Fp", o.Fp},
                                                      {"Fh", o.Fh},
                                                      {"Fb", o.Fb},
                                                      {"Fy", o.Fy},
                                                      {"Frr", o.Frr},
                                                      {"lS", o.lS},
                                                      {"lS_rate", o.lS_rate},
                                                      {"slip_angle", o.slip_angle},
                                                      {"omega", o.omega},
                                                      {"slip_ratio", o.slip_ratio},
                                                      {"Fx", o.Fx},
                                                      {"Mz", o.Mz},
                                                      {"kappa_law", o.kappa_law},
                                                      {"alpha_law", o.alpha_law},
                                                      {"camber", o.camber},
                                                      {"Mx", o.Mx},
                                                      {"My", o.My}};
    for (const auto& [name, v] : scalars) Finite(why, wheel, name, v);
    Finite(why, wheel, "F_W", o.F_W);
  }
  Finite(why, "", "drag Da", d.Da);
  Finite(why, "", "steering_torque", d.steering_torque);
  Finite(why, "", "F_W", d.F_W);
  Finite(why, "", "M_B", d.M_B);
  Finite(why, "", "a_WT_W", d.a_WT_W);
  Finite(why, "", "dw_B", d.dw_B);
  Finite(why, "", "w_eff_B", d.w_eff_B);
  Finite(why, "", "F_wall_W", d.F_wall_W);
  Finite(why, "", "engine_speed", d.drivetrain.engine_speed);
  Finite(why, "", "engine_torque", d.drivetrain.engine_torque);
  return why.empty() ? why : "invariant: " + why;
}

const char* StepStatusText(StepStatus status) {
  static_assert(kRunawaySpeedMps == 1000.0 && kRunawayRateRadps == 1000.0,
                "StepStatusText names the runaway limits");
  switch (status) {
    case StepStatus::kOk:
      return "";
    case StepStatus::kNonFinite:
      return "its state became non-finite";
    case StepStatus::kUnderGround:
      return "it fell through the ground (its wheels off the ground and its centre under it: it "
             "rolled over? this model has no contact of the body with the ground)";
    case StepStatus::kRunaway:
      return "its state ran away (faster than 1000 m/s or spinning faster than 1000 rad/s)";
  }
  return "";
}

StepStatus Simulator::Step() {
  const Terrain& terrain = world_->terrain;
  ws_.start = state_;

  // Stage: controls (latched input, speed control) and the horizontal traces, held for the step.
  record_.input = input_;
  record_.control = ComputeControls(params_.get(), input_, h_, state_);
  if (FindHeldContacts(params_.get(), terrain, state_.x, ws_.walls, ws_.edges)) {
    ++wall_traced_steps_;
  }

  // Stage: RK4 over the equations of motion; stage 0 is evaluated at x_n and is what we report.
  const AppliedControl& u = record_.control;
  auto f = [&](int stage, const StateVector& x, StateVector& xdot) {
    Derived& d = stage == 0 ? record_.derived : ws_.stage_derived;
    EvaluateModel(params_.get(), terrain, u, ws_.walls, ws_.edges, x, xdot, d, stage == 0);
  };
  Rk4Step(kClassicalRk4, f, h_, ws_.rk4, state_.x);

  // Stage: post-step.
  StateVector& x = state_.x;
  const double qn = x.segment<4>(sx::kQ).norm();
  if (!x.allFinite() || !(qn > 0.0)) {
    state_ = ws_.start;  // contain: the state stays at x_n
    ++nonfinite_steps_;
    return StepStatus::kNonFinite;
  }
  x.segment<4>(sx::kQ) /= qn;
  // Stage: a state that ran away (StepStatus::kRunaway): discarded like a non-finite one.
  if (Velocity(x).squaredNorm() > kRunawaySpeedMps * kRunawaySpeedMps ||
      AngularVelocityB(x).squaredNorm() > kRunawayRateRadps * kRunawayRateRadps) {
    state_ = ws_.start;
    ++runaway_steps_;
    return StepStatus::kRunaway;
  }
  // Stage: the body under the ground (StepStatus::kUnderGround). Only while no wheel touches it
  // (two traces then; none while driving): nothing below the centre T within 10 km, and the
  // ground above it.
  bool any_contact = false;
  for (const WheelOutputs& w : record_.derived.wheel) any_contact = any_contact || w.contact;
  if (!any_contact) {
    const Eigen::Vector3d p = Position(x);
    if (!terrain.Trace(p, -Eigen::Vector3d::UnitZ(), 1e4).hit &&
        terrain.Trace(p, Eigen::Vector3d::UnitZ(), 1e4).hit) {
      state_ = ws_.start;
      ++under_ground_steps_;
      return StepStatus::kUnderGround;
    }
  }
  if (params_->model == VehicleModel::kPaper && params_->yaw_mode == YawMode::kPaper &&
      ws_.stage_derived.any_contact) {
    // The yaw rate is eq. 6 of the new state (contact as seen by the last stage).
    const Eigen::Matrix3d R_WB = Orientation(x).toRotationMatrix();
    x[sx::kW + 2] = R_WB.col(0).dot(Velocity(x)) * std::sin(u.gamma) / params_->wheelbase;
  }
  record_.step = ws_.start.step;
  record_.t = static_cast<double>(ws_.start.step) * h_;
  record_.state = ws_.start;
  state_.step = ws_.start.step + 1;
  record_.hash_after = StateHash(state_);
  if (!CheckStepDemands(record_, state_, last_invariant_failure_, sizeof last_invariant_failure_)) {
    ++invariant_failures_;
  }
  if constexpr (kCheckInvariants) {
    if (std::string why = CheckStepInvariants(record_, state_); !why.empty()) InvariantFailed(why);
  }
  return StepStatus::kOk;
}

void Simulator::Forward(Derived& out, AppliedControl* control) const {
  State s = state_;
  const AppliedControl u = ComputeControls(params_.get(), input_, h_, s);
  if (control != nullptr) *control = u;
  WallPlanes walls;
  WheelEdges edges;
  FindHeldContacts(params_.get(), world_->terrain, state_.x, walls, edges);
  StateVector xdot;
  EvaluateModel(params_.get(), world_->terrain, u, walls, edges, state_.x, xdot, out, true);
}

}  // namespace vdyn
