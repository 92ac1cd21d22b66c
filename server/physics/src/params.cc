#include "vdyn/physics/params.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "vdyn/base/gearbox.h"
#include "vdyn/base/limits.h"
#include "vdyn/base/text.h"

namespace vdyn {
namespace {

using base::FormatApprox;
using base::FormatNumber;

// Where each limited field of the table lives in Params.
struct Field {
  std::string_view path;
  double (*get)(const Params&);
};
struct WheelField {
  std::string_view name;
  double WheelParams::*member;
};

// clang-format off
constexpr Field kFields[] = {
  {"mass", [](const Params& p) { return p.mass; }},
  {"ixx", [](const Params& p) { return p.inertia_B.x(); }},
  {"iyy", [](const Params& p) { return p.inertia_B.y(); }},
  {"izz", [](const Params& p) { return p.inertia_B.z(); }},
  {"b", [](const Params& p) { return p.b; }},
  {"c", [](const Params& p) { return p.c; }},
  {"b_l", [](const Params& p) { return p.b_l; }},
  {"b_p", [](const Params& p) { return p.b_p; }},
  {"mu", [](const Params& p) { return p.mu; }},
  {"cx", [](const Params& p) { return p.cx; }},
  {"rho", [](const Params& p) { return p.rho; }},
  {"sx", [](const Params& p) { return p.sx; }},
  {"ha", [](const Params& p) { return p.ha; }},
  {"rolling_resistance", [](const Params& p) { return p.rolling_resistance; }},
  {"drive_force_max", [](const Params& p) { return p.drive_force_max; }},
  {"drive_front_fraction", [](const Params& p) { return p.drive_front_fraction; }},
  {"brake_force_max", [](const Params& p) { return p.brake_force_max; }},
  {"brake_front_fraction", [](const Params& p) { return p.brake_front_fraction; }},
  {"steering_lock", [](const Params& p) { return p.steering_lock; }},
  {"tire_slip_speed", [](const Params& p) { return p.tire_slip_speed; }},
  {"cruise_kp", [](const Params& p) { return p.cruise_kp; }},
  {"cruise_ki", [](const Params& p) { return p.cruise_ki; }},
  {"body_front", [](const Params& p) { return p.body_front; }},
  {"body_rear", [](const Params& p) { return p.body_rear; }},
  {"body_half_width", [](const Params& p) { return p.body_half_width; }},
  {"body_probe_height", [](const Params& p) { return p.body_probe_height; }},
  {"wall_stiffness", [](const Params& p) { return p.wall_stiffness; }},
  {"wall_damping", [](const Params& p) { return p.wall_damping; }},
  {"wall_friction", [](const Params& p) { return p.wall_friction; }},
  {"gravity", [](const Params& p) { return p.gravity; }},
  {"steering_trail", [](const Params& p) { return p.steering_trail; }},
  {"steering_ratio", [](const Params& p) { return p.steering_ratio; }},
  {"mu_slide_ratio", [](const Params& p) { return p.mu_slide_ratio; }},
  {"tire_load_sensitivity", [](const Params& p) { return p.tire_load_sensitivity; }},
  {"tire_contact_half_length", [](const Params& p) { return p.tire_contact_half_length; }},
  {"tire_relaxation_long", [](const Params& p) { return p.tire_relaxation_long; }},
  {"tire_relaxation_lat", [](const Params& p) { return p.tire_relaxation_lat; }},
  {"tire_low_speed_damping", [](const Params& p) { return p.tire_low_speed_damping; }},
  {"tire_vertical_stiffness", [](const Params& p) { return p.tire_vertical_stiffness; }},
  {"engine_power_max", [](const Params& p) { return p.engine_power_max; }},
  {"engine_rpm_power_max", [](const Params& p) { return p.engine_rpm_power_max; }},
  {"engine_rpm_idle", [](const Params& p) { return p.engine_rpm_idle; }},
  {"engine_rpm_limit", [](const Params& p) { return p.engine_rpm_limit; }},
  {"engine_inertia", [](const Params& p) { return p.engine_inertia; }},
  {"engine_brake_torque", [](const Params& p) { return p.engine_brake_torque; }},
  {"clutch_torque_max", [](const Params& p) { return p.clutch_torque_max; }},
  {"clutch_engage_rpm", [](const Params& p) { return p.clutch_engage_rpm; }},
  {"clutch_stick_angle", [](const Params& p) { return p.clutch_stick_angle; }},
  {"brake_stick_angle", [](const Params& p) { return p.brake_stick_angle; }},
  {"stick_damping_time", [](const Params& p) { return p.stick_damping_time; }},
  {"gear_count", [](const Params& p) { return static_cast<double>(p.gear_count); }},
  {"gear_ratio_first", [](const Params& p) { return p.gear_ratio_first; }},
  {"gear_ratio_top", [](const Params& p) { return p.gear_ratio_top; }},
  {"gear_ratio_reverse", [](const Params& p) { return p.gear_ratio_reverse; }},
  {"final_drive_ratio", [](const Params& p) { return p.final_drive_ratio; }},
  {"drivetrain_efficiency", [](const Params& p) { return p.drivetrain_efficiency; }},
  {"shift_up_rpm", [](const Params& p) { return p.shift_up_rpm; }},
  {"shift_down_rpm", [](const Params& p) { return p.shift_down_rpm; }},
  {"shift_time", [](const Params& p) { return p.shift_time; }},
  {"handbrake_force_max", [](const Params& p) { return p.handbrake_force_max; }},
  {"abs", [](const Params& p) { return p.abs ? 1.0 : 0.0; }},
  {"traction_control", [](const Params& p) { return p.traction_control ? 1.0 : 0.0; }},
  {"caster_trail", [](const Params& p) { return p.caster_trail; }},
  {"scrub_radius", [](const Params& p) { return p.scrub_radius; }},
  {"ackermann", [](const Params& p) { return p.ackermann; }},
  {"steering_inertia", [](const Params& p) { return p.steering_inertia; }},
  {"steering_friction", [](const Params& p) { return p.steering_friction; }},
  {"steering_damping", [](const Params& p) { return p.steering_damping; }},
  {"steering_follow_frequency", [](const Params& p) { return p.steering_follow_frequency; }},
};
constexpr WheelField kWheelFieldsTable[] = {
  {"z_offset", &WheelParams::z_offset},
  {"spring_stiffness", &WheelParams::spring_stiffness},
  {"damper_coefficient", &WheelParams::damper_coefficient},
  {"free_length", &WheelParams::free_length},
  {"radius", &WheelParams::radius},
  {"cornering_stiffness", &WheelParams::cornering_stiffness},
  {"bump_stop_length", &WheelParams::bump_stop_length},
  {"bump_stop_stiffness", &WheelParams::bump_stop_stiffness},
  {"longitudinal_stiffness", &WheelParams::longitudinal_stiffness},
  {"nominal_load", &WheelParams::nominal_load},
  {"spin_inertia", &WheelParams::spin_inertia},
  {"min_length", &WheelParams::min_length},
  {"max_length", &WheelParams::max_length},
};
// clang-format on

void Check(std::string path, const limits::Range* range, double v, std::vector<ParamIssue>& out) {
  if (range == nullptr) {
    out.push_back({std::move(path), "internal: no limit in the table of limits"});
    return;
  }
  std::string why = limits::Check(*range, v);
  if (!why.empty()) out.push_back({std::move(path), std::move(why)});
}

constexpr double kRpm = 2.0 * 3.14159265358979323846 / 60.0;  // rad/s per rpm

// The full model's derived constants (docs/model.md, "The full model").
void DeriveFullModel(Params& p) {
  Params::Derived& d = p.full;
  const int n = p.gear_count;
  // Gear ratios in geometric progression from the first to the top gear.
  d.ratio_step = base::GearRatioStep(p.gear_ratio_first, p.gear_ratio_top, n);
  d.gear_ratio.fill(0.0);
  for (int g = 1; g <= n; ++g) {
    d.gear_ratio[g] = base::ForwardGearRatio(p.gear_ratio_first, p.gear_ratio_top, n, g);
  }
  // Brush law with adhesion limit mu_0 and sliding friction mu_slide (docs/model.md): with
  // r = mu_slide / mu_0 it peaks at z* = 1 / (3 - 2 r) with F / Fz = mu_0 g(r),
  // g(r) = 3 z* (1 - z*)^2 + r z*^2 (3 - 2 z*). mu is that peak: solve g(r) / r = mu / mu_slide
  // for r (g(r) / r falls from infinity at r -> 0 to 1 at r = 1) by bisection.
  auto peak_over_slide = [](double r) {
    const double z = 1.0 / (3.0 - 2.0 * r);
    return (3.0 * z * (1.0 - z) * (1.0 - z) + r * z * z * (3.0 - 2.0 * z)) / r;
  };
  d.mu_slide = p.mu * p.mu_slide_ratio;
  const double q = 1.0 / p.mu_slide_ratio;
  double lo = 1e-9, hi = 1.0;
  for (int i = 0; i < 100 && q > 1.0; ++i) {
    const double mid = 0.5 * (lo + hi);
    (peak_over_slide(mid) > q ? lo : hi) = mid;
  }
  const double r = q > 1.0 ? 0.5 * (lo + hi) : 1.0;
  d.mu_static = d.mu_slide / r;
  d.peak_z = 1.0 / (3.0 - 2.0 * r);
  const double f = p.drive_front_fraction;
  for (int w = 0; w < kNumWheels; ++w) {
    const WheelParams& wp = p.wheel[w];
    const bool front = IsFront(w);
    d.drive_share[w] = 0.5 * (front ? f : 1.0 - f);
    d.brake_torque[w] = 0.5 * p.brake_force_max *
                        (front ? p.brake_front_fraction : 1.0 - p.brake_front_fraction) * wp.radius;
    d.handbrake_torque[w] = front ? 0.0 : 0.5 * p.handbrake_force_max * wp.radius;
    // z = C_kappa kappa / (3 mu Fz) with C_kappa proportional to the load: kappa* is load-free.
    // A Magic Formula tyre's: where its Fx peaks at its nominal load.
    d.peak_slip[w] =
        wp.mf.enabled ? MagicFormulaPeaks(wp.mf, wp.mf.fnomin * wp.mf.lfzo).kappa
                      : d.peak_z * 3.0 * d.mu_static * wp.nominal_load / wp.longitudinal_stiffness;
    const double camber = w == kLF || w == kLR ? -wp.camber : wp.camber;
    d.camber_cos[w] = std::cos(camber);
    d.camber_sin[w] = std::sin(camber);
    d.tire_vertical_stiffness[w] = p.tire_vertical_stiffness;
    if (wp.mf.enabled && wp.mf.vertical_stiffness > 0.0) {
      const double dpi = (wp.mf.inflpres - wp.mf.nompres) / wp.mf.nompres;
      d.tire_vertical_stiffness[w] = wp.mf.vertical_stiffness * (1.0 + wp.mf.pfz1 * dpi);
    }
    const double x = 1.0 / p.tire_load_sensitivity;  // sin(2 atan x) = 2x / (1 + x^2)
    d.load_sensitivity_norm[w] = (1.0 + x * x) / (2.0 * x);
  }
  d.omega_idle = p.engine_rpm_idle * kRpm;
  d.omega_limit = p.engine_rpm_limit * kRpm;
  d.omega_power = p.engine_rpm_power_max * kRpm;
  d.omega_engage = p.clutch_engage_rpm * kRpm;
  d.omega_shift_up = p.shift_up_rpm * kRpm;
  d.omega_shift_down = p.shift_down_rpm * kRpm;
  d.engine_torque_base = p.engine_power_max / d.omega_power;
  d.track = p.b_l + p.b_p;
  d.ackermann_offset = 0.5 * p.ackermann * d.track;
  d.hand_wheel_lock = p.steering_lock * p.steering_ratio;
}

void DeriveParams(Params& p) {
  p.wheelbase = p.b + p.c;
  for (WheelParams& wp : p.wheel) {
    if (!wp.mf.enabled) continue;
    DeriveMagicFormula(wp.mf);
    wp.radius = wp.mf.unloaded_radius;  // the tyre file's free radius
  }
  // Mount points A in the body frame (X forward, Y left, Z up), the paper's Fig. 4:
  //   LF (+b, +bL)   RF (+b, -bP)
  //   LR (-c, +bL)   RR (-c, -bP)     each z_offset below T.
  const double x[kNumWheels] = {p.b, p.b, -p.c, -p.c};
  const double y[kNumWheels] = {p.b_l, -p.b_p, p.b_l, -p.b_p};
  for (int w = 0; w < kNumWheels; ++w) {
    p.p_TA_B[w] = Eigen::Vector3d(x[w], y[w], -p.wheel[w].z_offset);
  }
  // Body box seen from above, O at its probe height above T; probes 0-3 end on the faces,
  // probes 4-7 at the corners:
  //        7 ------ 2 ------ 4        Y (left)
  //        |                 |        ^
  //        1        O        0        +--> X (forward)
  //        |                 |
  //        6 ------ 3 ------ 5
  p.p_TO_B = Eigen::Vector3d(0.0, 0.0, p.body_probe_height);
  const double f = p.body_front, r = p.body_rear, hw = p.body_half_width;
  const Eigen::Vector2d ends[Params::kNumProbes] = {{f, 0},   {-r, 0},   {0, hw},  {0, -hw},
                                                    {f, hw},  {f, -hw},  {-r, -hw}, {-r, hw}};
  for (int k = 0; k < Params::kNumProbes; ++k) {
    p.probe_length[k] = ends[k].norm();
    p.probe_dir_B[k] = Eigen::Vector3d(ends[k].x(), ends[k].y(), 0.0) / p.probe_length[k];
  }
  DeriveFullModel(p);
}

// A Magic Formula tyre's coefficients: every one present and finite, and the values the equations
// divide by or take a peak from on the right side (field paths lf.magic_formula.pdy1).
void AddMagicFormulaIssues(const MagicFormula& m, const std::string& prefix,
                           std::vector<ParamIssue>& out) {
  const std::size_t issues_before = out.size();
  bool finite = true;
  for (const MagicFormulaField& f : MagicFormulaFields()) {
    if (!std::isfinite(m.*f.member)) {
      out.push_back(
          {prefix + std::string(f.name), std::isnan(f.fallback) && std::isnan(m.*f.member)
                                             ? "missing: the Magic Formula's equations need it"
                                             : "must be a finite number"});
      finite = false;
    }
  }
  if (!finite) return;
  auto need = [&](bool ok, const char* field, const std::string& why) {
    if (!ok) out.push_back({prefix + field, why});
  };
  constexpr double kHalfPi = 1.5707963267948966;
  need(m.fnomin > 0.0 && m.fnomin <= 1e6, "fnomin", "the nominal load must be in (0, 1e6] N");
  need(m.lfzo > 0.0, "lfzo", "the nominal load's scale must be positive");
  // A tyre's radius, 5 cm to 3 m: a file whose [UNITS] LENGTH does not match its numbers (metre
  // values under 'millimeter') is caught here instead of driving a car on 0.3 mm wheels.
  need(m.unloaded_radius >= 0.05 && m.unloaded_radius <= 3.0, "unloaded_radius",
       FormatApprox(m.unloaded_radius) +
           " m is not a tyre's radius (0.05 to 3 m): does [UNITS] LENGTH match the file's "
           "numbers?");
  need(m.longvl > 0.0, "longvl", "the nominal speed must be positive");
  need(m.vxlow > 0.0, "vxlow", "must be positive");
  need(m.nompres > 0.0, "nompres", "the nominal pressure must be positive");
  need(m.inflpres > 0.0, "inflpres", "the inflation pressure must be positive");
  need(m.longitudinal_stiffness > 0.0, "longitudinal_stiffness", "must be positive");
  need(m.lateral_stiffness > 0.0, "lateral_stiffness", "must be positive");
  need(m.vertical_stiffness >= 0.0, "vertical_stiffness",
       "must not be negative (0: the vehicle's)");
  need(m.pcx1 * m.lcx > 1.0, "pcx1",
       "the shape factor PCX1 * LCX must exceed 1 (a curve with a peak)");
  need(m.pcy1 * m.lcy > 1.0, "pcy1",
       "the shape factor PCY1 * LCY must exceed 1 (a curve with a peak)");
  need(m.pdx1 * m.lmux > 0.0, "pdx1", "the friction PDX1 * LMUX must be positive");
  need(m.pdy1 * m.lmuy > 0.0, "pdy1", "the friction PDY1 * LMUY must be positive");
  // No tyre grips with ten times its load (road tyres 0.8-1.3, racing slicks about 2): a file
  // with PDY1 = 1e300 was taken and gave side forces of 4e301 N.
  need(m.pdx1 * m.lmux <= 10.0, "pdx1",
       "the friction PDX1 * LMUX is " + FormatApprox(m.pdx1 * m.lmux) +
           ": more than 10 times the load, which no tyre carries (road tyres 0.8-1.3)");
  need(m.pdy1 * m.lmuy <= 10.0, "pdy1",
       "the friction PDY1 * LMUY is " + FormatApprox(m.pdy1 * m.lmuy) +
           ": more than 10 times the load, which no tyre carries (road tyres 0.8-1.3)");
  need(m.kpumin < 0.0 && m.kpumax > 0.0, "kpumin",
       "KPUMIN < 0 < KPUMAX: the range holds zero slip");
  need(m.alpmin > -kHalfPi && m.alpmin < 0.0 && m.alpmax > 0.0 && m.alpmax < kHalfPi, "alpmin",
       "-pi/2 < ALPMIN < 0 < ALPMAX < pi/2");
  need(m.cammin < m.cammax, "cammin", "CAMMIN must be below CAMMAX");
  need(m.presmin < m.presmax, "presmin", "PRESMIN must be below PRESMAX");
  need(m.fzmax >= m.fnomin * m.lfzo, "fzmax",
       "FZMAX (" + FormatApprox(m.fzmax) + " N) is below the nominal load FNOMIN * LFZO (" +
           FormatApprox(m.fnomin * m.lfzo) + " N): every load above it would be taken as FZMAX");
  if (out.size() != issues_before) return;
  // The slip stiffnesses at the nominal load: Fx along the slip, Fy against it (TNO's signs).
  const MfLoad L = MagicFormulaLoad(m, m.fnomin * m.lfzo, 0.0, m.inflpres);
  need(L.Kxk > 0.0, "pkx1",
       "the slip stiffness Kxk at FNOMIN is " + FormatApprox(L.Kxk) + " N: it must be positive");
  need(L.Kya < 0.0, "pky1",
       "the cornering stiffness Kya at FNOMIN is " + FormatApprox(L.Kya) +
           " N/rad: it must be negative (the side force opposes the slip, ISO signs as TNO's)");
  // Slip stiffnesses of a tyre are some 10 to 40 times its load (per unit slip, per radian).
  const double fz0 = m.fnomin * m.lfzo;
  need(L.Kxk <= 1000.0 * fz0, "pkx1",
       "the slip stiffness Kxk at FNOMIN is " + FormatApprox(L.Kxk) + " N, " +
           FormatApprox(L.Kxk / fz0) + " times the load: more than 1000 times is no tyre's");
  need(-L.Kya <= 1000.0 * fz0, "pky1",
       "the cornering stiffness Kya at FNOMIN is " + FormatApprox(L.Kya) + " N/rad, " +
           FormatApprox(-L.Kya / fz0) + " times the load: more than 1000 times is no tyre's");
}

// Rules between the full model's parameters (each named by the field a user would change).
void CheckFullModel(const Params& p, std::vector<ParamIssue>& out) {
  auto need = [&out](bool ok, const char* field, std::string why) {
    if (!ok) out.push_back({field, std::move(why)});
  };
  need(p.engine_rpm_idle < p.engine_rpm_limit, "engine_rpm_idle",
       "must be below engine_rpm_limit (" + FormatNumber(p.engine_rpm_limit) + ")");
  need(p.clutch_engage_rpm > p.engine_rpm_idle, "clutch_engage_rpm",
       "must be above engine_rpm_idle (" + FormatNumber(p.engine_rpm_idle) + ")");
  need(p.shift_down_rpm > p.clutch_engage_rpm, "shift_down_rpm",
       "must be above clutch_engage_rpm (" + FormatNumber(p.clutch_engage_rpm) +
           "), or the automatic would let the clutch slip before it shifts down");
  need(p.shift_up_rpm <= p.engine_rpm_limit, "shift_up_rpm",
       "must not exceed engine_rpm_limit (" + FormatNumber(p.engine_rpm_limit) + ")");
  need(p.gear_ratio_top <= p.gear_ratio_first, "gear_ratio_top",
       "must not exceed gear_ratio_first (" + FormatNumber(p.gear_ratio_first) + ")");
  if (p.gear_count > 1 && p.gear_ratio_top <= p.gear_ratio_first) {
    // After an upshift at shift_up_rpm the engine must land above shift_down_rpm, or the
    // automatic would shift back at once.
    const double step = base::GearRatioStep(p.gear_ratio_first, p.gear_ratio_top, p.gear_count);
    need(p.shift_up_rpm * step > p.shift_down_rpm, "shift_down_rpm",
         "must be below shift_up_rpm times the ratio step between gears (" +
             FormatNumber(p.shift_up_rpm * step) + " rpm), or the automatic would hunt");
  }
  // Ackermann: the outer wheel's angle needs L - offset * tan(lock) > 0; keep a margin.
  const double offset = 0.5 * std::abs(p.ackermann) * (p.b_l + p.b_p);
  need(offset * std::tan(p.steering_lock) < 0.8 * (p.b + p.c), "ackermann",
       "with this track and steering_lock the outer wheel would turn past 90 degrees");
}

}  // namespace

std::vector<ParamIssue> CheckMagicFormula(const MagicFormula& mf, const std::string& prefix) {
  std::vector<ParamIssue> out;
  AddMagicFormulaIssues(mf, prefix, out);
  return out;
}

std::string FormatIssues(const std::vector<ParamIssue>& issues) {
  std::string s;
  for (const ParamIssue& i : issues) {
    if (!s.empty()) s += "; ";
    s += i.field + ": " + i.reason;
  }
  return s;
}

std::vector<ParamIssue> CheckParams(const Params& p) {
  std::vector<ParamIssue> out;
  for (const Field& f : kFields) Check(std::string(f.path), limits::ParamRange(f.path), f.get(p), out);
  for (int w = 0; w < kNumWheels; ++w) {
    const std::string prefix = std::string(kWheelFields[w]) + ".";
    const WheelParams& wp = p.wheel[w];
    for (const WheelField& f : kWheelFieldsTable) {
      const std::string path = prefix + std::string(f.name);
      Check(path, limits::ParamRange(path), wp.*f.member, out);
    }
    if (wp.bump_stop_length >= wp.free_length) {
      out.push_back({prefix + "bump_stop_length",
                     "must be shorter than free_length (" + FormatNumber(wp.free_length) +
                         " m), got " + FormatNumber(wp.bump_stop_length)});
    }
    if (wp.max_length > wp.free_length) {
      out.push_back({prefix + "max_length", "the rebound stop must not be beyond free_length (" +
                                                FormatNumber(wp.free_length) + " m), got " +
                                                FormatNumber(wp.max_length)});
    }
    if (wp.min_length >= wp.max_length) {
      out.push_back({prefix + "min_length", "the end of travel must be shorter than max_length (" +
                                                FormatNumber(wp.max_length) + " m), got " +
                                                FormatNumber(wp.min_length)});
    }
    if (!(std::abs(wp.camber) <= 0.3)) {
      out.push_back({prefix + "camber",
                     "static camber must be in [-0.3, 0.3] rad, got " + FormatNumber(wp.camber)});
    }
    if (wp.mf.enabled) AddMagicFormulaIssues(wp.mf, prefix + "magic_formula.", out);
    if (wp.mf.enabled && p.model == VehicleModel::kPaper) {
      out.push_back({prefix + "magic_formula",
                     "the paper model has no tyre law to give it (it would read only the file's "
                     "radius): use the full model, or no tyre file"});
    }
    if (p.model == VehicleModel::kFull && !(wp.damper_coefficient > 0.0)) {
      out.push_back({prefix + "damper_coefficient",
                     "must be positive for the full model (the wheel's travel is set by it)"});
    }
  }
  CheckFullModel(p, out);
  // A rigid body's principal moments obey the triangle inequality (each <= the sum of the others).
  const double i[3] = {p.inertia_B.x(), p.inertia_B.y(), p.inertia_B.z()};
  const char* names[3] = {"ixx", "iyy", "izz"};
  for (int k = 0; k < 3; ++k) {
    if (i[k] > i[(k + 1) % 3] + i[(k + 2) % 3]) {
      out.push_back({names[k], "exceeds the sum of the other two principal moments (" +
                                   FormatNumber(i[(k + 1) % 3] + i[(k + 2) % 3]) +
                                   "): no rigid body has such inertia"});
    }
  }
  if (p.body_front < p.b) {
    out.push_back({"body_front", "must reach at least the front axle (b = " + FormatNumber(p.b) + " m)"});
  }
  if (p.body_rear < p.c) {
    out.push_back({"body_rear", "must reach at least the rear axle (c = " + FormatNumber(p.c) + " m)"});
  }
  if (!out.empty()) return out;  // the rules below need every value in range
  // The car rests on its springs: the static load compresses each spring by less than its travel
  // to the bump stop.
  for (int w = 0; w < kNumWheels; ++w) {
    const WheelParams& wp = p.wheel[w];
    const double sag = StaticWheelLoad(p, w) / wp.spring_stiffness;
    const double travel = wp.free_length - wp.bump_stop_length;
    if (!(sag < travel)) {
      out.push_back({std::string(kWheelFields[w]) + ".spring_stiffness",
                     "the static load (" + FormatApprox(StaticWheelLoad(p, w)) +
                         " N) compresses this spring by " + FormatApprox(sag) +
                         " m, more than its travel to the bump stop (" + FormatApprox(travel) +
                         " m): it needs at least " +
                         FormatApprox(StaticWheelLoad(p, w) / travel) + " N/m"});
    }
    // The full model's tyre is a radial spring too: the static load compresses it by less than a
    // fifth of its radius (a passenger tyre: 5 %), or the car starts with its wheels in the
    // ground and sinks (a soft or negative stiffness was accepted: it fell for ever).
    if (p.model != VehicleModel::kFull) continue;
    const bool from_file = wp.mf.enabled && wp.mf.vertical_stiffness > 0.0;
    const double k_tyre =
        from_file ? wp.mf.vertical_stiffness *
                        (1.0 + wp.mf.pfz1 * (wp.mf.inflpres - wp.mf.nompres) / wp.mf.nompres)
                  : p.tire_vertical_stiffness;
    const double radius = wp.mf.enabled ? wp.mf.unloaded_radius : wp.radius;
    const double limit = 0.2 * radius;
    const std::string field = from_file ? std::string(kWheelFields[w]) +
                                              ".magic_formula.vertical_stiffness"
                                        : std::string("tire_vertical_stiffness");
    const std::string what = from_file ? " (VERTICAL_STIFFNESS (1 + PFZ1 dpi) at INFLPRES)" : "";
    if (!(k_tyre > 0.0)) {
      out.push_back({field, "the " + std::string(kWheelNames[w]) + " tyre's vertical stiffness" +
                                what + " is " + FormatApprox(k_tyre) +
                                " N/m: it must be positive"});
    } else if (!(StaticWheelLoad(p, w) / k_tyre < limit)) {
      out.push_back({field, "the static load (" + FormatApprox(StaticWheelLoad(p, w)) +
                                " N) compresses the " + std::string(kWheelNames[w]) + " tyre" +
                                what + " by " + FormatApprox(StaticWheelLoad(p, w) / k_tyre) +
                                " m, more than a fifth of its radius (" + FormatApprox(limit) +
                                " m): it needs at least " +
                                FormatApprox(StaticWheelLoad(p, w) / limit) + " N/m"});
    }
  }
  return out;
}

double StaticWheelLoad(const Params& p, int w) {
  const double wheelbase = p.b + p.c;
  const double axle = IsFront(w) ? p.c / wheelbase : p.b / wheelbase;
  const bool left = w == kLF || w == kLR;
  const double side = left ? p.b_p / (p.b_l + p.b_p) : p.b_l / (p.b_l + p.b_p);
  return p.mass * p.gravity * axle * side;
}

double MaxResolvedStep(const Params& p, std::string* why) {
  double best = std::numeric_limits<double>::infinity();
  auto limit = [&](double h, const std::string& mode) {
    if (h < best) {
      best = h;
      if (why != nullptr) *why = mode;
    }
  };
  const double x[kNumWheels] = {p.b, p.b, -p.c, -p.c};
  const double y[kNumWheels] = {p.b_l, -p.b_p, p.b_l, -p.b_p};
  double roll_spring = 0, pitch_spring = 0, roll_stop = 0, pitch_stop = 0;
  for (int w = 0; w < kNumWheels; ++w) {
    const WheelParams& wp = p.wheel[w];
    const double m_corner = StaticWheelLoad(p, w) / p.gravity;
    const std::string name(kWheelNames[w]);
    limit(1.0 / std::sqrt(wp.spring_stiffness / m_corner), name + " spring (heave)");
    limit(2.0 / std::sqrt((wp.spring_stiffness + wp.bump_stop_stiffness) / m_corner),
          name + " bump stop");
    if (wp.damper_coefficient > 0.0) limit(2.5 / (wp.damper_coefficient / m_corner), name + " damper");
    roll_spring += wp.spring_stiffness * y[w] * y[w];
    pitch_spring += wp.spring_stiffness * x[w] * x[w];
    roll_stop += (wp.spring_stiffness + wp.bump_stop_stiffness) * y[w] * y[w];
    pitch_stop += (wp.spring_stiffness + wp.bump_stop_stiffness) * x[w] * x[w];
  }
  limit(1.0 / std::sqrt(roll_spring / p.inertia_B.x()), "roll on the springs");
  limit(1.0 / std::sqrt(pitch_spring / p.inertia_B.y()), "pitch on the springs");
  limit(2.0 / std::sqrt(roll_stop / p.inertia_B.x()), "roll on the bump stops");
  limit(2.0 / std::sqrt(pitch_stop / p.inertia_B.y()), "pitch on the bump stops");
  limit(2.0 / std::sqrt(p.wall_stiffness / p.mass), "wall contact");
  if (p.model == VehicleModel::kFull) {
    // The stick-slip (LuGre) elements: a stuck brake or clutch is a torsional spring of stiffness
    // capacity / stick angle with damping capacity * stick_damping_time / stick angle; at a held
    // brake the tire's deflection adds C_kappa R^2 / sigma_kappa (docs/model.md, 8.6).
    const Params::Derived& d = p.full;
    for (int w = 0; w < kNumWheels; ++w) {
      const WheelParams& wp = p.wheel[w];
      const std::string name(kWheelNames[w]);
      const double k_brake = (d.brake_torque[w] + d.handbrake_torque[w]) / p.brake_stick_angle;
      // A Magic Formula tyre: its carcass stiffness Cx (= Kxk / sigma_kappa) at twice its
      // nominal load, at most.
      const double k_tire =
          wp.mf.enabled
              ? MagicFormulaLoad(wp.mf, 2.0 * wp.mf.fnomin * wp.mf.lfzo, 0.0, wp.mf.inflpres).Cx *
                    wp.radius * wp.radius
              : wp.longitudinal_stiffness * wp.radius * wp.radius / p.tire_relaxation_long;
      limit(2.0 / std::sqrt((k_brake + k_tire) / wp.spin_inertia), name + " wheel on a held brake");
      // The contact patch's relaxation at speed, a real pole at -|v| / sigma (8.2): stable up to
      // the fastest a vehicle is spawned or teleported (limits::kSpawnSpeed), h |v| / sigma <=
      // 2.78 (RK4 on the negative real axis: 2.785). A Magic Formula tyre's lengths at its
      // nominal load.
      double sigma_long = p.tire_relaxation_long, sigma_lat = p.tire_relaxation_lat;
      if (wp.mf.enabled) {
        const MfLoad L = MagicFormulaLoad(wp.mf, wp.mf.fnomin * wp.mf.lfzo, 0.0, wp.mf.inflpres);
        sigma_long = std::max(L.sigma_kappa, kMfMinRelaxationLength);
        sigma_lat = std::max(L.sigma_alpha, kMfMinRelaxationLength);
      }
      const double v_max = limits::kSpawnSpeed.hi;
      const std::string at = " at " + FormatApprox(v_max) + " m/s";
      limit(2.78 * sigma_long / v_max, name + " tyre relaxation, longitudinal," + at);
      limit(2.78 * sigma_lat / v_max, name + " tyre relaxation, lateral," + at);
      if (p.stick_damping_time > 0.0) {
        limit(2.5 / (k_brake * p.stick_damping_time / wp.spin_inertia), name + " brake stick damping");
      }
    }
    const double k_clutch = p.clutch_torque_max / p.clutch_stick_angle;
    limit(2.0 / std::sqrt(k_clutch / p.engine_inertia), "engine on a stuck clutch");
    if (p.stick_damping_time > 0.0) {
      limit(2.5 / (k_clutch * p.stick_damping_time / p.engine_inertia), "clutch stick damping");
    }
    // The steering column follows the driver's angle as a critically damped pair of poles at -f.
    limit(2.5 / p.steering_follow_frequency, "steering column follower");
    if (p.steering_damping > 0.0) {
      limit(2.5 / (p.steering_damping / p.steering_inertia), "steering column damping");
    }
  }
  return best;
}

std::string CheckStep(const ValidParams& p, double h) {
  if (h <= p.max_step()) return {};
  std::string mode;
  MaxResolvedStep(p.get(), &mode);
  return "the step " + FormatApprox(h) + " s is too long for these parameters: their fastest mode (" +
         mode + ") needs h <= " + FormatApprox(p.max_step(), 3) + " s";
}

std::optional<ValidParams> Validate(Params p, std::vector<ParamIssue>* issues) {
  std::vector<ParamIssue> found = CheckParams(p);
  if (!found.empty()) {
    if (issues != nullptr) *issues = std::move(found);
    return std::nullopt;
  }
  DeriveParams(p);
  ValidParams v;
  v.p_ = p;
  v.max_step_ = MaxResolvedStep(p);
  return v;
}

}  // namespace vdyn
