#include "vdyn/base/limits.h"

#include <algorithm>
#include <cmath>

#include "vdyn/base/text.h"

namespace vdyn::limits {
namespace {

// clang-format off
constexpr ParamLimit kParams[] = {
  {"mass",                 {0, 1e5, true, false, "vehicle mass, kg"}},
  {"ixx",                  {0, 1e7, true, false, "roll moment of inertia (about X), kg*m^2"}},
  {"iyy",                  {0, 1e7, true, false, "pitch moment of inertia (about Y), kg*m^2"}},
  {"izz",                  {0, 1e7, true, false, "yaw moment of inertia (about Z), kg*m^2"}},
  {"b",                    {0, 20, true, false, "distance T to front axle, m"}},
  {"c",                    {0, 20, true, false, "distance T to rear axle, m"}},
  {"b_l",                  {0, 5, true, false, "distance T to left wheels, m"}},
  {"b_p",                  {0, 5, true, false, "distance T to right wheels, m"}},
  {"mu",                   {0, 3, true, false, "friction coefficient"}},
  {"cx",                   {0, 5, false, false, "drag coefficient"}},
  {"rho",                  {0, 10, false, false, "air density, kg/m^3"}},
  {"sx",                   {0, 50, false, false, "frontal area, m^2"}},
  {"ha",                   {-5, 5, false, false, "drag height above T, m"}},
  {"rolling_resistance",   {0, 0.5, false, false, "rolling resistance coefficient"}},
  {"drive_force_max",      {0, 1e6, false, false, "drive force, N"}},
  {"drive_front_fraction", {0, 1, false, false, "share of drive force on the front axle"}},
  {"brake_force_max",      {0, 1e6, false, false, "brake force, N"}},
  {"brake_front_fraction", {0, 1, false, false, "share of brake force on the front axle"}},
  {"steering_lock",        {0, 1.5, true, false, "steering lock, rad (below pi/2)"}},
  {"tire_slip_speed",      {0, 10, true, false, "slip regularisation speed, m/s"}},
  {"cruise_kp",            {0, 100, false, false, "cruise proportional gain, 1/(m/s)"}},
  {"cruise_ki",            {0, 100, false, false, "cruise integral gain, 1/m"}},
  {"body_front",           {0, 20, true, false, "body extent ahead of T, m"}},
  {"body_rear",            {0, 20, true, false, "body extent behind T, m"}},
  {"body_half_width",      {0, 5, true, false, "body half width, m"}},
  {"body_probe_height",    {-5, 5, false, false, "height of the horizontal traces above T, m"}},
  {"wall_stiffness",       {0, 1e9, true, false, "wall contact stiffness, N/m"}},
  {"wall_damping",         {0, 10, false, false, "wall contact damping factor, s/m"}},
  {"wall_friction",        {0, 3, false, false, "wall friction coefficient"}},
  {"gravity",              {0, 100, false, false, "gravitational acceleration, m/s^2"}},
  {"steering_trail",       {-0.5, 0.5, false, false, "steering trail, m"}},
  {"steering_ratio",       {1, 100, false, false, "steering ratio (hand wheel / road wheel)"}},
  // The full model (docs/model.md, "The full model").
  {"mu_slide_ratio",       {0.025, 1, false, false, "sliding friction / peak friction"}},
  {"tire_load_sensitivity", {0, 100, true, false, "load of the largest cornering stiffness, in nominal loads"}},
  {"tire_contact_half_length", {0, 1, true, false, "contact patch half length, m"}},
  {"tire_relaxation_long", {0, 10, true, false, "longitudinal relaxation length, m"}},
  {"tire_relaxation_lat",  {0, 10, true, false, "lateral relaxation length, m"}},
  {"tire_low_speed_damping", {0, 1e6, false, false, "tire damping at low speed, N*s/m"}},
  {"tire_vertical_stiffness", {0, 1e8, true, false, "tire vertical stiffness, N/m"}},
  {"engine_power_max",     {0, 1e7, true, false, "engine power, W"}},
  {"engine_rpm_power_max", {0, 30000, true, false, "engine speed at peak power, rpm"}},
  {"engine_rpm_idle",      {0, 30000, true, false, "engine idle speed, rpm"}},
  {"engine_rpm_limit",     {0, 30000, true, false, "engine speed limit, rpm"}},
  {"engine_inertia",       {0, 100, true, false, "engine inertia, kg*m^2"}},
  {"engine_brake_torque",  {0, 1e5, false, false, "engine braking torque at the speed limit, N*m"}},
  {"clutch_torque_max",    {0, 1e5, true, false, "clutch torque capacity, N*m"}},
  {"clutch_engage_rpm",    {0, 30000, true, false, "engine speed of full clutch engagement, rpm"}},
  {"clutch_stick_angle",   {0, 10, true, false, "clutch stick (wind-up) angle, rad"}},
  {"brake_stick_angle",    {0, 1, true, false, "brake stick angle, rad"}},
  {"stick_damping_time",   {0, 1, false, false, "stick damping time, s"}},
  {"gear_count",           {1, 10, false, false, "number of forward gears"}},
  {"gear_ratio_first",     {0, 100, true, false, "first gear ratio"}},
  {"gear_ratio_top",       {0, 100, true, false, "top gear ratio"}},
  {"gear_ratio_reverse",   {0, 100, true, false, "reverse gear ratio"}},
  {"final_drive_ratio",    {0, 100, true, false, "final drive ratio"}},
  {"drivetrain_efficiency", {0, 1, true, false, "drivetrain efficiency"}},
  {"shift_up_rpm",         {0, 30000, true, false, "automatic upshift speed, rpm"}},
  {"shift_down_rpm",       {0, 30000, true, false, "automatic downshift speed, rpm"}},
  {"shift_time",           {0, 5, false, false, "gear shift time, s"}},
  {"handbrake_force_max",  {0, 1e6, false, false, "handbrake force, N"}},
  {"abs",                  {0, 1, false, false, "ABS on or off"}},
  {"traction_control",     {0, 1, false, false, "traction control on or off"}},
  {"caster_trail",         {-0.5, 0.5, false, false, "caster trail, m"}},
  {"scrub_radius",         {-0.5, 0.5, false, false, "scrub radius, m"}},
  {"ackermann",            {-1, 1, false, false, "Ackermann fraction"}},
  {"steering_inertia",     {0, 10, true, false, "steering inertia at the hand wheel, kg*m^2"}},
  {"steering_friction",    {0, 100, false, false, "steering friction at the hand wheel, N*m"}},
  {"steering_damping",     {0, 100, false, false, "steering damping at the hand wheel, N*m*s/rad"}},
  {"steering_follow_frequency", {0, 2000, true, false, "steering follow frequency, rad/s"}},
};
constexpr ParamLimit kWheel[] = {
  {"z_offset",             {-3, 3, false, false, "T to mount point A, m"}},
  {"spring_stiffness",     {0, 1e8, true, false, "spring stiffness, N/m"}},
  {"damper_coefficient",   {0, 1e7, false, false, "damping coefficient, N*s/m"}},
  {"free_length",          {0, 5, true, false, "spring free length, m"}},
  {"radius",               {0, 3, true, false, "wheel radius, m"}},
  {"cornering_stiffness",  {0, 1e7, true, false, "cornering stiffness, N/rad"}},
  {"bump_stop_length",     {0, 5, false, false, "bump stop engagement length, m"}},
  {"bump_stop_stiffness",  {0, 1e9, false, false, "bump stop stiffness, N/m"}},
  {"longitudinal_stiffness", {0, 1e7, true, false, "longitudinal slip stiffness, N"}},
  {"nominal_load",         {0, 1e6, true, false, "tire nominal load, N"}},
  {"spin_inertia",         {0, 100, true, false, "wheel spin inertia, kg*m^2"}},
  {"min_length",           {0, 5, false, false, "spring length at the end of travel, m"}},
  {"max_length",           {0, 5, true, false, "spring length at the rebound stop, m"}},
};
constexpr ParamChoice kChoices[] = {
  {"model",        "vehicle model (the equations: full or the paper's)"},
  {"yaw_mode",     "yaw equation (paper model)"},
  {"tire_law",     "tire law (paper model)"},
  {"differential", "differential of the driven axles (full model)"},
  {"lf",           "left front wheel (LF)"},
  {"rf",           "right front wheel (RF)"},
  {"lr",           "left rear wheel (LR)"},
  {"rr",           "right rear wheel (RR)"},
};
// Optional fields (absent: what their words say), the per-wheel ones by their name alone.
constexpr ParamChoice kOptional[] = {
  {"tire_file",       "a .tir tyre file for every wheel, relative to the parameter file (files only)"},
  {"tire_file_front", "a .tir tyre file for the front wheels (files only)"},
  {"tire_file_rear",  "a .tir tyre file for the rear wheels (files only)"},
};
constexpr ParamChoice kWheelOptional[] = {
  {"magic_formula", "Magic Formula tyre: a .tir file's coefficients (absent: the brush law)"},
  {"camber",        "static camber, rad, within 0.3 (negative: top inboard; absent: 0)"},
  {"tire_file",     "a .tir tyre file for this wheel, relative to the parameter file (files only)"},
};
// clang-format on

}  // namespace

std::string Describe(const Range& r) {
  return std::string(r.lo_open ? "(" : "[") + base::FormatNumber(r.lo) + ", " +
         base::FormatNumber(r.hi) + (r.hi_open ? ")" : "]");
}

std::string Check(const Range& r, double v) {
  if (!std::isfinite(v)) {
    return std::string(r.what) + " must be a finite number, got " + base::FormatNumber(v);
  }
  const bool low = r.lo_open ? v <= r.lo : v < r.lo;
  const bool high = r.hi_open ? v >= r.hi : v > r.hi;
  if (low || high) {
    return std::string(r.what) + " must be in " + Describe(r) + ", got " + base::FormatNumber(v);
  }
  return {};
}

double Clamp(const Range& r, double v, double fallback) {
  if (!std::isfinite(v)) return fallback;
  return std::clamp(v, r.lo, r.hi);
}

std::span<const ParamLimit> VehicleParamLimits() { return kParams; }
std::span<const ParamLimit> WheelParamLimits() { return kWheel; }

const Range* ParamRange(std::string_view path) {
  for (const ParamLimit& l : kParams) {
    if (l.path == path) return &l.range;
  }
  const std::size_t dot = path.find('.');
  if (dot != std::string_view::npos) {
    const std::string_view field = path.substr(dot + 1);
    for (const ParamLimit& l : kWheel) {
      if (l.path == field) return &l.range;
    }
  }
  return nullptr;
}

std::string_view ParamWords(std::string_view path) {
  if (const Range* r = ParamRange(path)) return r->what;
  for (const ParamChoice& c : kChoices) {
    if (c.path == path) return c.what;
  }
  for (const ParamChoice& c : kOptional) {
    if (c.path == path) return c.what;
  }
  if (const std::size_t dot = path.find('.'); dot != std::string_view::npos) {
    for (const ParamChoice& c : kWheelOptional) {
      if (c.path == path.substr(dot + 1)) return c.what;
    }
  }
  return {};
}

}  // namespace vdyn::limits
