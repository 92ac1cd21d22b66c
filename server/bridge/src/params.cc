#include "vdyn/bridge/params.h"

#include <algorithm>
#include <cctype>
#include <set>

#include "vdyn/base/limits.h"

namespace vdyn {
namespace {

namespace gp = google::protobuf;

const pb::WheelParams& Wheel(const pb::VehicleParams& m, int w) {
  switch (w) {
    case kLF: return m.lf();
    case kRF: return m.rf();
    case kLR: return m.lr();
    default: return m.rr();
  }
}

// The coefficients' fields of the message, in the physics' table order.
const std::vector<const gp::FieldDescriptor*>& TireFields() {
  static const std::vector<const gp::FieldDescriptor*> fields = [] {
    std::vector<const gp::FieldDescriptor*> v;
    for (const MagicFormulaField& f : MagicFormulaFields()) {
      v.push_back(pb::MagicFormulaTire::descriptor()->FindFieldByName(std::string(f.name)));
    }
    return v;
  }();
  return fields;
}

// A Magic Formula tyre from its message: each coefficient given, or its fallback (NaN for the
// required ones: Validate names them).
MagicFormula TireFromProto(const pb::MagicFormulaTire& t) {
  MagicFormula m;
  m.enabled = true;
  m.side = t.tyreside() == "RIGHT" ? -1 : t.tyreside() == "SYMMETRIC" ? 0 : 1;
  const gp::Reflection* r = t.GetReflection();
  const auto fields = MagicFormulaFields();
  for (std::size_t i = 0; i < fields.size(); ++i) {
    const gp::FieldDescriptor* f = TireFields()[i];
    m.*fields[i].member =
        f != nullptr && r->HasField(t, f) ? r->GetDouble(t, f) : fields[i].fallback;
  }
  return m;
}

// The plain struct from the message, field by field (no checks).
Params RawParams(const pb::VehicleParams& m) {
  Params p;
  p.mass = m.mass();
  p.inertia_B = Eigen::Vector3d(m.ixx(), m.iyy(), m.izz());
  p.b = m.b();
  p.c = m.c();
  p.b_l = m.b_l();
  p.b_p = m.b_p();
  for (int w = 0; w < kNumWheels; ++w) {
    const pb::WheelParams& s = Wheel(m, w);
    WheelParams& d = p.wheel[w];
    d.z_offset = s.z_offset();
    d.spring_stiffness = s.spring_stiffness();
    d.damper_coefficient = s.damper_coefficient();
    d.free_length = s.free_length();
    d.radius = s.radius();
    d.cornering_stiffness = s.cornering_stiffness();
    d.bump_stop_length = s.bump_stop_length();
    d.bump_stop_stiffness = s.bump_stop_stiffness();
    d.longitudinal_stiffness = s.longitudinal_stiffness();
    d.nominal_load = s.nominal_load();
    d.spin_inertia = s.spin_inertia();
    d.min_length = s.min_length();
    d.max_length = s.max_length();
    d.camber = s.has_camber() ? s.camber() : 0.0;
    if (s.has_magic_formula()) d.mf = TireFromProto(s.magic_formula());
  }
  p.mu = m.mu();
  p.cx = m.cx();
  p.rho = m.rho();
  p.sx = m.sx();
  p.ha = m.ha();
  p.rolling_resistance = m.rolling_resistance();
  p.drive_force_max = m.drive_force_max();
  p.drive_front_fraction = m.drive_front_fraction();
  p.brake_force_max = m.brake_force_max();
  p.brake_front_fraction = m.brake_front_fraction();
  p.steering_lock = m.steering_lock();
  p.yaw_mode = m.yaw_mode() == pb::YAW_MODE_PAPER ? YawMode::kPaper : YawMode::kDynamic;
  p.tire_law = m.tire_law() == pb::TIRE_LAW_LINEAR_SATURATED ? TireLaw::kLinearSaturated
                                                               : TireLaw::kFiala;
  p.tire_slip_speed = m.tire_slip_speed();
  p.cruise_kp = m.cruise_kp();
  p.cruise_ki = m.cruise_ki();
  p.body_front = m.body_front();
  p.body_rear = m.body_rear();
  p.body_half_width = m.body_half_width();
  p.body_probe_height = m.body_probe_height();
  p.wall_stiffness = m.wall_stiffness();
  p.wall_damping = m.wall_damping();
  p.wall_friction = m.wall_friction();
  p.gravity = m.gravity();
  p.steering_trail = m.steering_trail();
  p.steering_ratio = m.steering_ratio();
  p.model = m.model() == pb::VEHICLE_MODEL_PAPER ? VehicleModel::kPaper : VehicleModel::kFull;
  p.mu_slide_ratio = m.mu_slide_ratio();
  p.tire_load_sensitivity = m.tire_load_sensitivity();
  p.tire_contact_half_length = m.tire_contact_half_length();
  p.tire_relaxation_long = m.tire_relaxation_long();
  p.tire_relaxation_lat = m.tire_relaxation_lat();
  p.tire_low_speed_damping = m.tire_low_speed_damping();
  p.tire_vertical_stiffness = m.tire_vertical_stiffness();
  p.engine_power_max = m.engine_power_max();
  p.engine_rpm_power_max = m.engine_rpm_power_max();
  p.engine_rpm_idle = m.engine_rpm_idle();
  p.engine_rpm_limit = m.engine_rpm_limit();
  p.engine_inertia = m.engine_inertia();
  p.engine_brake_torque = m.engine_brake_torque();
  p.clutch_torque_max = m.clutch_torque_max();
  p.clutch_engage_rpm = m.clutch_engage_rpm();
  p.clutch_stick_angle = m.clutch_stick_angle();
  p.brake_stick_angle = m.brake_stick_angle();
  p.stick_damping_time = m.stick_damping_time();
  // The table of limits refuses more than 10 gears; clamp first so the cast cannot overflow.
  p.gear_count = static_cast<int>(std::min<std::uint32_t>(m.gear_count(), 1000u));
  p.gear_ratio_first = m.gear_ratio_first();
  p.gear_ratio_top = m.gear_ratio_top();
  p.gear_ratio_reverse = m.gear_ratio_reverse();
  p.final_drive_ratio = m.final_drive_ratio();
  p.drivetrain_efficiency = m.drivetrain_efficiency();
  p.shift_up_rpm = m.shift_up_rpm();
  p.shift_down_rpm = m.shift_down_rpm();
  p.shift_time = m.shift_time();
  p.differential = m.differential() == pb::DIFFERENTIAL_LOCKED ? Differential::kLocked
                                                                : Differential::kOpen;
  p.handbrake_force_max = m.handbrake_force_max();
  p.abs = m.abs();
  p.traction_control = m.traction_control();
  p.caster_trail = m.caster_trail();
  p.scrub_radius = m.scrub_radius();
  p.ackermann = m.ackermann();
  p.steering_inertia = m.steering_inertia();
  p.steering_friction = m.steering_friction();
  p.steering_damping = m.steering_damping();
  p.steering_follow_frequency = m.steering_follow_frequency();
  return p;
}

bool Has(const gp::Message& msg, std::string_view name) {
  const gp::FieldDescriptor* f = msg.GetDescriptor()->FindFieldByName(std::string(name));
  return f != nullptr && msg.GetReflection()->HasField(msg, f);
}

// An enum field: present, not UNSPECIFIED, and one of the enum's values.
void CheckEnum(const gp::Message& msg, const char* name, std::vector<ParamIssue>& out) {
  const gp::FieldDescriptor* f = msg.GetDescriptor()->FindFieldByName(name);
  const gp::EnumDescriptor* e = f->enum_type();
  std::string choices;
  for (int i = 1; i < e->value_count(); ++i) {
    choices += (choices.empty() ? "" : " or ") + e->value(i)->name();
  }
  if (!msg.GetReflection()->HasField(msg, f)) {
    out.push_back({name, "missing (" + choices + ")"});
    return;
  }
  const int v = msg.GetReflection()->GetEnumValue(msg, f);
  if (v == 0 || e->FindValueByNumber(v) == nullptr) {
    out.push_back({name, std::to_string(v) + " is not one of " + choices});
  }
}

// A tyre message's own fields (the coefficients are the physics' to check).
void CheckTireMessage(const pb::MagicFormulaTire& t, const std::string& tp,
                      std::vector<ParamIssue>& out) {
  if (t.fittyp() != 61 && t.fittyp() != 62) {
    out.push_back({tp + "fittyp", std::to_string(t.fittyp()) +
                                      " is not a model vdyn evaluates (61: MF 6.1, 62: MF 6.2)"});
  }
  if (!t.tyreside().empty() && t.tyreside() != "LEFT" && t.tyreside() != "RIGHT" &&
      t.tyreside() != "SYMMETRIC") {
    out.push_back({tp + "tyreside", "must be LEFT, RIGHT or SYMMETRIC"});
  }
  if (t.name().size() > limits::kMaxNameBytes) {
    out.push_back({tp + "name", "longer than " + std::to_string(limits::kMaxNameBytes) + " bytes"});
  }
}

// A missing coefficient's reason names the tyre file and the key as the file writes it.
void NameTireFiles(const pb::VehicleParams& msg, std::vector<ParamIssue>& issues) {
  for (ParamIssue& i : issues) {
    const std::size_t at = i.field.find(".magic_formula.");
    if (at == std::string::npos || i.reason.rfind("missing", 0) != 0) continue;
    const int w = static_cast<int>(
        std::find(kWheelFields.begin(), kWheelFields.end(), i.field.substr(0, at)) -
        kWheelFields.begin());
    if (w >= kNumWheels) continue;
    std::string key = i.field.substr(at + 15);
    for (char& c : key) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    const std::string& name = Wheel(msg, w).magic_formula().name();
    i.reason = "missing from the tyre file" + (name.empty() ? std::string() : " '" + name + "'") +
               " (" + key + "): the Magic Formula's equations need it";
  }
}

// What only a message can get wrong about tyres: a file name where the coefficients belong, a
// model version or side the physics does not know, a name too long.
void CheckTires(const pb::VehicleParams& msg, std::vector<ParamIssue>& out) {
  constexpr const char* kFileOnly =
      "a tyre file is read where a parameter file is loaded; a message carries its coefficients "
      "(magic_formula)";
  if (msg.has_tire_file()) out.push_back({"tire_file", kFileOnly});
  if (msg.has_tire_file_front()) out.push_back({"tire_file_front", kFileOnly});
  if (msg.has_tire_file_rear()) out.push_back({"tire_file_rear", kFileOnly});
  for (int w = 0; w < kNumWheels; ++w) {
    const pb::WheelParams& wp = Wheel(msg, w);
    const std::string prefix = std::string(kWheelFields[w]) + ".";
    if (wp.has_tire_file()) out.push_back({prefix + "tire_file", kFileOnly});
    if (!wp.has_magic_formula()) continue;
    CheckTireMessage(wp.magic_formula(), prefix + "magic_formula.", out);
  }
}

}  // namespace

std::vector<ParamIssue> ValidateVehicleParams(const pb::VehicleParams& msg) {
  std::vector<ParamIssue> out;
  std::set<std::string> missing;
  for (const limits::ParamLimit& l : limits::VehicleParamLimits()) {
    if (!Has(msg, l.path)) missing.insert(std::string(l.path));
  }
  for (int w = 0; w < kNumWheels; ++w) {
    for (const limits::ParamLimit& l : limits::WheelParamLimits()) {
      if (!Has(Wheel(msg, w), l.path)) {
        missing.insert(std::string(kWheelFields[w]) + "." + std::string(l.path));
      }
    }
  }
  for (const std::string& m : missing) out.push_back({m, "missing"});
  CheckEnum(msg, "model", out);
  CheckEnum(msg, "yaw_mode", out);
  CheckEnum(msg, "tire_law", out);
  CheckEnum(msg, "differential", out);
  CheckTires(msg, out);
  const Params raw = RawParams(msg);
  for (ParamIssue& i : CheckParams(raw)) {
    if (missing.count(i.field) != 0) continue;
    if (i.field == "gear_count" && static_cast<std::uint64_t>(raw.gear_count) != msg.gear_count()) {
      // RawParams clamps a count too large for an int: the reason names the number given, as
      // a whole number (4000000000, not 4e9).
      const limits::Range& r = *limits::ParamRange("gear_count");
      i.reason = std::string(r.what) + " must be in " + limits::Describe(r) + ", got " +
                 std::to_string(msg.gear_count());
    }
    out.push_back(std::move(i));
  }
  NameTireFiles(msg, out);
  return out;
}

MagicFormula MagicFormulaFromProto(const pb::MagicFormulaTire& tire) {
  std::vector<ParamIssue> issues;
  CheckTireMessage(tire, "magic_formula.", issues);
  MagicFormula m = TireFromProto(tire);
  if (issues.empty()) issues = CheckMagicFormula(m, "magic_formula.");
  if (!issues.empty()) {
    throw ParamsError((tire.name().empty() ? std::string("tyre") : tire.name()) + ": " +
                      FormatIssues(issues));
  }
  DeriveMagicFormula(m);
  return m;
}

ValidParams ParamsFromProto(const pb::VehicleParams& msg) {
  std::vector<ParamIssue> issues = ValidateVehicleParams(msg);
  if (issues.empty()) {
    std::optional<ValidParams> v = Validate(RawParams(msg), &issues);
    if (v) return *v;
  }
  throw ParamsError("invalid vehicle parameters: " + FormatIssues(issues));
}

pb::VehicleParams ParseVehicleParams(const std::string& text, bool json,
                                     const std::string& source_name,
                                     const pb::VehicleParams& base) {
  pb::VehicleParams merged = ParseVehicleParamsText(text, json, source_name, base);
  const std::vector<ParamIssue> issues = ValidateVehicleParams(merged);
  if (!issues.empty()) throw ParamsError(source_name + ": " + FormatIssues(issues));
  return merged;
}

pb::VehicleParams LoadVehicleParamsFile(const std::filesystem::path& path,
                                        const pb::VehicleParams& base) {
  pb::VehicleParams merged = ReadVehicleParamsFile(path, base);
  const std::vector<ParamIssue> issues = ValidateVehicleParams(merged);
  if (!issues.empty()) throw ParamsError(path.string() + ": " + FormatIssues(issues));
  return merged;
}

}  // namespace vdyn
