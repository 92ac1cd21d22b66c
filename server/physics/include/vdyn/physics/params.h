// Vehicle parameters: the SI, plain-struct form the physics reads in its step, and the only way to
// give it to a simulator: validated (ValidParams).
//
// Data kinds are kept apart (docs/architecture.md): parameters are validated once, at the edge,
// and replaced only between steps; the step reads them and never changes them. The limits come
// from the one table (vdyn/base/limits.h); the field names in issues are the paths of
// proto/vdyn/vehicle_params.proto ("lf.free_length"), so a reply or a file error names the field
// the user wrote.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "vdyn/physics/magic_formula.h"
#include "vdyn/physics/state.h"

namespace vdyn {

// Wheel order everywhere: Left Front, Right Front, Left Rear, Right Rear (the paper's suffixes).
enum WheelIndex : int { kLF = 0, kRF = 1, kLR = 2, kRR = 3 };
inline constexpr int kNumWheels = 4;
inline constexpr std::array<std::string_view, kNumWheels> kWheelNames = {"LF", "RF", "LR", "RR"};
inline constexpr std::array<std::string_view, kNumWheels> kWheelFields = {"lf", "rf", "lr", "rr"};
inline constexpr bool IsFront(int w) { return w == kLF || w == kRF; }

enum class YawMode { kDynamic, kPaper };
enum class TireLaw { kFiala, kLinearSaturated };
enum class Differential { kOpen, kLocked };
inline constexpr int kMaxGears = 10;

struct WheelParams {
  double z_offset = 0;            // m, T down to mount point A along -Z_B
  double spring_stiffness = 0;    // N/m   (paper: c)
  double damper_coefficient = 0;  // N*s/m (paper: k)
  double free_length = 0;         // m
  double radius = 0;              // m
  double cornering_stiffness = 0; // N/rad
  double bump_stop_length = 0;    // m
  double bump_stop_stiffness = 0; // N/m
  // Full model only.
  double longitudinal_stiffness = 0;  // N per unit slip ratio, at the nominal load
  double nominal_load = 0;            // N: the load the tire stiffnesses are given at
  double spin_inertia = 0;            // kg*m^2: wheel, tire, hub, brake disc, half shaft
  double min_length = 0;              // m: the spring's end of travel (bump)
  double max_length = 0;              // m: the rebound stop (the wheel hangs here)
  double camber = 0;                  // rad, static; negative leans the top inboard
  // A Magic Formula tyre (mf.enabled): its law replaces the brush law on this wheel, and its
  // UNLOADED_RADIUS the radius above (docs/model.md, 8.2b).
  MagicFormula mf;
};

struct Params {
  double mass = 0;
  Eigen::Vector3d inertia_B = Eigen::Vector3d::Zero();  // principal moments about T, kg*m^2
  double b = 0, c = 0, b_l = 0, b_p = 0;
  std::array<WheelParams, kNumWheels> wheel{};
  double mu = 0;
  double cx = 0, rho = 0, sx = 0, ha = 0;
  double rolling_resistance = 0;
  double drive_force_max = 0, drive_front_fraction = 0;
  double brake_force_max = 0, brake_front_fraction = 0;
  double steering_lock = 0;
  YawMode yaw_mode = YawMode::kDynamic;
  TireLaw tire_law = TireLaw::kFiala;
  double tire_slip_speed = 0;
  double cruise_kp = 0, cruise_ki = 0;
  double body_front = 0, body_rear = 0, body_half_width = 0, body_probe_height = 0;
  double wall_stiffness = 0, wall_damping = 0 /* s/m */, wall_friction = 0;
  double gravity = 0;
  double steering_trail = 0;  // m (paper model)
  double steering_ratio = 1;  // hand wheel / road wheel

  // --- The full model (docs/model.md, "The full model"); the paper's model reads none of these.
  VehicleModel model = VehicleModel::kPaper;
  // Tire: brush model with static (mu) and sliding (mu_slide) friction, relaxation, compliance.
  double mu_slide_ratio = 0;           // sliding friction / mu (the peak)
  double tire_load_sensitivity = 0;    // C_alpha is largest at this many nominal loads
  double tire_contact_half_length = 0; // m, at the nominal load
  double tire_relaxation_long = 0;     // m
  double tire_relaxation_lat = 0;      // m
  double tire_low_speed_damping = 0;   // N*s/m
  double tire_vertical_stiffness = 0;  // N/m
  // Engine, clutch, gearbox, differentials.
  double engine_power_max = 0;         // W
  double engine_rpm_power_max = 0;     // rpm
  double engine_rpm_idle = 0;          // rpm
  double engine_rpm_limit = 0;         // rpm
  double engine_inertia = 0;           // kg*m^2
  double engine_brake_torque = 0;      // N*m at the rev limit, closed throttle
  double clutch_torque_max = 0;        // N*m
  double clutch_engage_rpm = 0;        // rpm: the automatic clutch is fully engaged from here
  double clutch_stick_angle = 0;       // rad (LuGre breakaway angle at the engine)
  double brake_stick_angle = 0;        // rad (LuGre breakaway angle at the wheel)
  double stick_damping_time = 0;       // s (LuGre sigma1 / sigma0)
  int gear_count = 1;
  double gear_ratio_first = 0, gear_ratio_top = 0, gear_ratio_reverse = 0;
  double final_drive_ratio = 0;
  double drivetrain_efficiency = 0;
  double shift_up_rpm = 0, shift_down_rpm = 0;  // rpm
  double shift_time = 0;                        // s
  Differential differential = Differential::kOpen;
  double handbrake_force_max = 0;  // N, summed over the rear wheels
  bool abs = false;
  bool traction_control = false;
  // Steering system.
  double caster_trail = 0;          // m, the steering axis meets the ground this far ahead of B
  double scrub_radius = 0;          // m, ... and this far inboard of B
  double ackermann = 0;             // 0 parallel steering, 1 full Ackermann
  double steering_inertia = 0;      // kg*m^2 at the hand wheel
  double steering_friction = 0;     // N*m at the hand wheel
  double steering_damping = 0;      // N*m*s/rad at the hand wheel
  double steering_follow_frequency = 0;  // rad/s: how fast the column follows a commanded angle

  // Derived once, when the parameters are validated (never inside a step).
  std::array<Eigen::Vector3d, kNumWheels> p_TA_B{};  // mount points A from T, body frame
  double wheelbase = 0;                                // b + c
  // Horizontal traces (the paper's C-D): from O (probe_height above T) towards the body box's
  // four faces and four corners; a probe's point S is where its ray leaves the box.
  static constexpr int kNumProbes = 8;
  Eigen::Vector3d p_TO_B = Eigen::Vector3d::Zero();
  std::array<Eigen::Vector3d, kNumProbes> probe_dir_B{};  // unit
  std::array<double, kNumProbes> probe_length{};          // |OS|, m
  // Full model, derived.
  struct Derived {
    std::array<double, kMaxGears + 1> gear_ratio{};  // [1..gear_count]; [0] unused
    std::array<double, kNumWheels> drive_share{};    // c_i: share of the gearbox torque per wheel
    std::array<double, kNumWheels> brake_torque{};   // N*m per wheel at full pedal
    std::array<double, kNumWheels> handbrake_torque{};  // N*m per wheel at full lever
    std::array<double, kNumWheels> peak_slip{};      // slip ratio at the brush law's peak
    std::array<double, kNumWheels> load_sensitivity_norm{};  // 1 / sin(2 atan(1 / p))
    // The tyre's radial stiffness per wheel: a Magic Formula tyre's VERTICAL_STIFFNESS (with its
    // pressure term) where the file gives one, else tire_vertical_stiffness. N/m.
    std::array<double, kNumWheels> tire_vertical_stiffness{};
    // cos and sin of the static camber about the wheel's heading, as the inclination reads it
    // (minus camber on the left wheels, plus on the right).
    std::array<double, kNumWheels> camber_cos{}, camber_sin{};
    double mu_slide = 0;         // sliding friction coefficient, mu * mu_slide_ratio
    double mu_static = 0;        // the brush's adhesion limit mu_0, so that the peak is mu
    double peak_z = 1;           // normalised slip of the law's peak (1: no peak)
    double omega_idle = 0, omega_limit = 0, omega_power = 0, omega_engage = 0;  // rad/s
    double omega_shift_up = 0, omega_shift_down = 0;                            // rad/s
    double engine_torque_base = 0;  // P_max / omega_power, N*m
    double track = 0;               // bL + bP, m
    double ackermann_offset = 0;    // ackermann * track / 2, m
    double hand_wheel_lock = 0;     // steering_lock * steering_ratio, rad
    double ratio_step = 1;          // geometric step between neighbouring gears (< 1)
  } full;
};

// One rejected value: the field's path ("lf.free_length") and why.
struct ParamIssue {
  std::string field;
  std::string reason;
};
// Joins issues as "field: reason; field: reason".
std::string FormatIssues(const std::vector<ParamIssue>& issues);

// Parameters that passed validation, with their derived members filled. A simulator accepts
// nothing else. Read them as a Params (implicit conversion, or get()).
class ValidParams {
 public:
  const Params& get() const { return p_; }
  const Params* operator->() const { return &p_; }
  operator const Params&() const { return p_; }  // NOLINT: read-only view, on purpose
  // The largest integration step that resolves these parameters' fastest modes, s (see
  // MaxResolvedStep). A simulator with a longer step refuses them.
  double max_step() const { return max_step_; }

 private:
  friend std::optional<ValidParams> Validate(Params p, std::vector<ParamIssue>* issues);
  ValidParams() = default;
  Params p_;
  double max_step_ = 0;
};

// Checks every value against the table of limits and the rules between them (a bump stop inside
// the spring's travel, the static load carried by the spring within its travel, a rigid body's
// inertia, a body that reaches its axles). Empty when valid.
std::vector<ParamIssue> CheckParams(const Params& p);
// A Magic Formula tyre's coefficients: each one the equations need present and finite, and the
// values they divide by or take a peak from on the right side; each issue's field is `prefix` and
// the coefficient ("lf.magic_formula.pdy1"). Empty when usable (CheckParams runs it per wheel).
std::vector<ParamIssue> CheckMagicFormula(const MagicFormula& mf, const std::string& prefix);
// The validated parameters with their derived members, or nullopt and the issues.
std::optional<ValidParams> Validate(Params p, std::vector<ParamIssue>* issues = nullptr);

// Static load of wheel w on level ground, N: m g (c or b)/L * (bP or bL)/(bL + bP).
double StaticWheelLoad(const Params& p, int w);

// The largest step h, s, at which RK4 still resolves the fastest modes of the parameters: every
// suspension mode (heave per corner, roll, pitch) with h * omega <= 1 (six steps a period), the
// stiff contacts (bump stops, walls) with h * omega <= 2, and the dampers' decay with h * rate
// <= 2.5 (RK4's real-axis limit is 2.79). `why` (if given) names the mode that sets it.
double MaxResolvedStep(const Params& p, std::string* why = nullptr);

// The issue for running parameters at step h (empty when max_step() >= h), e.g. "the step
// 0.05 s is too long for these parameters: ... needs h <= 0.035 s".
std::string CheckStep(const ValidParams& p, double h);

}  // namespace vdyn
