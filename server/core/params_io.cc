#include "params_io.h"

#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>

namespace vdyn {
namespace {

namespace gp = google::protobuf;

pb::WheelParams MakeWheel(double z_offset, double stiffness, double damping, double cornering) {
  pb::WheelParams w;
  w.set_z_offset(z_offset);
  w.set_spring_stiffness(stiffness);
  w.set_damper_coefficient(damping);
  w.set_free_length(0.35);
  w.set_radius(0.32);
  w.set_cornering_stiffness(cornering);
  w.set_bump_stop_length(0.06);
  w.set_bump_stop_stiffness(300000.0);
  return w;
}

// A range rule for one double field, by its path in the message.
struct Rule {
  const char* path;
  double lo;
  double hi;
  bool lo_open;  // lo itself is not allowed
  const char* what;
};

constexpr double kInf = std::numeric_limits<double>::infinity();

// clang-format off
constexpr Rule kRules[] = {
  {"mass", 0, 1e5, true, "vehicle mass, kg"},
  {"ixx", 0, 1e7, true, "moment of inertia, kg*m^2"},
  {"iyy", 0, 1e7, true, "moment of inertia, kg*m^2"},
  {"izz", 0, 1e7, true, "moment of inertia, kg*m^2"},
  {"b", 0, 20, true, "distance T to front axle, m"},
  {"c", 0, 20, true, "distance T to rear axle, m"},
  {"b_l", 0, 5, true, "distance T to left wheels, m"},
  {"b_p", 0, 5, true, "distance T to right wheels, m"},
  {"mu", 0, 3, true, "friction coefficient"},
  {"cx", 0, 5, false, "drag coefficient"},
  {"rho", 0, 10, false, "air density, kg/m^3"},
  {"sx", 0, 50, false, "frontal area, m^2"},
  {"ha", -5, 5, false, "drag height above T, m"},
  {"rolling_resistance", 0, 0.5, false, "rolling resistance coefficient"},
  {"drive_force_max", 0, 1e6, false, "drive force, N"},
  {"drive_front_fraction", 0, 1, false, "share of drive force on the front axle"},
  {"brake_force_max", 0, 1e6, false, "brake force, N"},
  {"brake_front_fraction", 0, 1, false, "share of brake force on the front axle"},
  {"steering_lock", 0, 1.5, true, "steering lock, rad (below pi/2)"},
  {"tire_slip_speed", 0, 10, true, "slip regularisation speed, m/s"},
  {"cruise_kp", 0, 100, false, "cruise proportional gain, 1/(m/s)"},
  {"cruise_ki", 0, 100, false, "cruise integral gain, 1/m"},
  {"body_front", 0, 20, true, "body extent ahead of T, m"},
  {"body_rear", 0, 20, true, "body extent behind T, m"},
  {"body_half_width", 0, 5, true, "body half width, m"},
  {"body_probe_height", -5, 5, false, "height of the horizontal traces above T, m"},
  {"wall_stiffness", 0, 1e9, true, "wall contact stiffness, N/m"},
  {"wall_damping", 0, 10, false, "wall contact damping factor, s/m"},
  {"wall_friction", 0, 3, false, "wall friction coefficient"},
  {"gravity", 0, 100, false, "gravitational acceleration, m/s^2"},
  {"steering_trail", -0.5, 0.5, false, "steering trail, m"},
  {"steering_ratio", 1, 100, false, "steering ratio (hand wheel / road wheel)"},
};
constexpr Rule kWheelRules[] = {
  {"z_offset", -3, 3, false, "T to mount point A, m"},
  {"spring_stiffness", 0, 1e8, true, "spring stiffness, N/m"},
  {"damper_coefficient", 0, 1e7, false, "damping coefficient, N*s/m"},
  {"free_length", 0, 5, true, "spring free length, m"},
  {"radius", 0, 3, true, "wheel radius, m"},
  {"cornering_stiffness", 0, 1e7, true, "cornering stiffness, N/rad"},
  {"bump_stop_length", 0, 5, false, "bump stop engagement length, m"},
  {"bump_stop_stiffness", 0, 1e9, false, "bump stop stiffness, N/m"},
};
// clang-format on

std::string FormatDouble(double v) {
  std::ostringstream os;
  os.precision(17);
  os << v;
  return os.str();
}

void CheckRule(const gp::Message& msg, const Rule& rule, const std::string& prefix,
               std::vector<ParamIssue>& out) {
  const gp::Descriptor* d = msg.GetDescriptor();
  const gp::FieldDescriptor* f = d->FindFieldByName(rule.path);
  const gp::Reflection* r = msg.GetReflection();
  const std::string name = prefix + rule.path;
  if (f == nullptr || f->cpp_type() != gp::FieldDescriptor::CPPTYPE_DOUBLE) {
    out.push_back({name, "internal: no such double field"});
    return;
  }
  if (!r->HasField(msg, f)) {
    out.push_back({name, "missing"});
    return;
  }
  const double v = r->GetDouble(msg, f);
  if (!std::isfinite(v)) {
    out.push_back({name, "must be a finite number (" + std::string(rule.what) + "), got " +
                             FormatDouble(v)});
    return;
  }
  const bool low = rule.lo_open ? v <= rule.lo : v < rule.lo;
  if (low || v > rule.hi) {
    out.push_back({name, std::string(rule.what) + " must be in " + (rule.lo_open ? "(" : "[") +
                             FormatDouble(rule.lo) + ", " + FormatDouble(rule.hi) + "], got " +
                             FormatDouble(v)});
  }
}

class CollectErrors : public gp::io::ErrorCollector {
 public:
  void AddError(int line, gp::io::ColumnNumber column, const std::string& message) override {
    if (!text.empty()) text += "; ";
    text += "line " + std::to_string(line + 1) + ", column " + std::to_string(column + 1) + ": " +
            message;
  }
  void AddWarning(int line, gp::io::ColumnNumber column, const std::string& message) override {
    AddError(line, column, "warning: " + message);
  }
  std::string text;
};

YawMode ToYawMode(pb::YawMode m) {
  return m == pb::YAW_MODE_PAPER ? YawMode::kPaper : YawMode::kDynamic;
}
TireLaw ToTireLaw(pb::TireLaw t) {
  return t == pb::TIRE_LAW_LINEAR_SATURATED ? TireLaw::kLinearSaturated : TireLaw::kFiala;
}

}  // namespace

pb::VehicleParams DefaultVehicleParams() {
  pb::VehicleParams p;
  p.set_mass(1500.0);
  p.set_ixx(550.0);
  p.set_iyy(2400.0);
  p.set_izz(2700.0);
  p.set_b(1.2);
  p.set_c(1.5);
  p.set_b_l(0.78);
  p.set_b_p(0.78);
  // Front: 4.09 kN static load per wheel, 1.35 Hz ride, damping ratio ~0.3.
  *p.mutable_lf() = MakeWheel(0.02, 30000.0, 2200.0, 65000.0);
  *p.mutable_rf() = MakeWheel(0.02, 30000.0, 2200.0, 65000.0);
  // Rear: 3.27 kN static load per wheel, 1.38 Hz ride; stiffer tires make the car understeer.
  *p.mutable_lr() = MakeWheel(0.02, 25000.0, 1800.0, 75000.0);
  *p.mutable_rr() = MakeWheel(0.02, 25000.0, 1800.0, 75000.0);
  p.set_mu(0.9);
  p.set_cx(0.30);
  p.set_rho(1.225);
  p.set_sx(2.2);
  p.set_ha(0.10);
  p.set_rolling_resistance(0.012);
  p.set_drive_force_max(6000.0);
  p.set_drive_front_fraction(1.0);
  p.set_brake_force_max(15000.0);
  p.set_brake_front_fraction(0.65);
  p.set_steering_lock(0.6);
  p.set_yaw_mode(pb::YAW_MODE_DYNAMIC);
  p.set_tire_law(pb::TIRE_LAW_FIALA);
  p.set_tire_slip_speed(0.5);
  p.set_cruise_kp(0.6);
  p.set_cruise_ki(0.15);
  p.set_body_front(2.2);
  p.set_body_rear(2.5);
  p.set_body_half_width(0.9);
  p.set_body_probe_height(0.0);
  p.set_wall_stiffness(5.0e6);
  p.set_wall_damping(0.5);
  p.set_wall_friction(0.3);
  p.set_gravity(9.81);
  p.set_steering_trail(0.04);
  p.set_steering_ratio(15.0);
  return p;
}

std::vector<ParamIssue> ValidateVehicleParams(const pb::VehicleParams& msg) {
  std::vector<ParamIssue> out;
  for (const Rule& rule : kRules) CheckRule(msg, rule, "", out);
  const std::pair<const char*, const pb::WheelParams*> wheels[] = {
      {"lf", &msg.lf()}, {"rf", &msg.rf()}, {"lr", &msg.lr()}, {"rr", &msg.rr()}};
  for (const auto& [name, w] : wheels) {
    const std::string prefix = std::string(name) + ".";
    for (const Rule& rule : kWheelRules) CheckRule(*w, rule, prefix, out);
    if (w->has_bump_stop_length() && w->has_free_length() &&
        w->bump_stop_length() >= w->free_length()) {
      out.push_back({prefix + "bump_stop_length", "must be shorter than free_length (" +
                                                      FormatDouble(w->free_length()) + " m), got " +
                                                      FormatDouble(w->bump_stop_length())});
    }
  }
  if (!msg.has_yaw_mode() || msg.yaw_mode() == pb::YAW_MODE_UNSPECIFIED) {
    out.push_back({"yaw_mode", "missing (YAW_MODE_DYNAMIC or YAW_MODE_PAPER)"});
  }
  if (!msg.has_tire_law() || msg.tire_law() == pb::TIRE_LAW_UNSPECIFIED) {
    out.push_back({"tire_law", "missing (TIRE_LAW_FIALA or TIRE_LAW_LINEAR_SATURATED)"});
  }
  // A rigid body's principal moments obey the triangle inequality (each <= the sum of the others).
  const double i[3] = {msg.ixx(), msg.iyy(), msg.izz()};
  const char* names[3] = {"ixx", "iyy", "izz"};
  for (int k = 0; k < 3; ++k) {
    if (i[k] > i[(k + 1) % 3] + i[(k + 2) % 3]) {
      out.push_back({names[k], "exceeds the sum of the other two principal moments (" +
                                   FormatDouble(i[(k + 1) % 3] + i[(k + 2) % 3]) +
                                   "): no rigid body has such inertia"});
    }
  }
  if (msg.has_body_front() && msg.has_b() && msg.body_front() < msg.b()) {
    out.push_back({"body_front", "must reach at least the front axle (b = " +
                                     FormatDouble(msg.b()) + " m)"});
  }
  if (msg.has_body_rear() && msg.has_c() && msg.body_rear() < msg.c()) {
    out.push_back({"body_rear", "must reach at least the rear axle (c = " +
                                    FormatDouble(msg.c()) + " m)"});
  }
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

pb::VehicleParams MergeVehicleParams(const pb::VehicleParams& base,
                                     const pb::VehicleParams& update) {
  pb::VehicleParams out = base;
  out.MergeFrom(update);  // proto3 `optional`: only fields present in `update` override
  return out;
}

Params ParamsFromProto(const pb::VehicleParams& m) {
  const std::vector<ParamIssue> issues = ValidateVehicleParams(m);
  if (!issues.empty()) throw ParamsError("invalid vehicle parameters: " + FormatIssues(issues));
  Params p;
  p.mass = m.mass();
  p.inertia_B = Eigen::Vector3d(m.ixx(), m.iyy(), m.izz());
  p.b = m.b();
  p.c = m.c();
  p.b_l = m.b_l();
  p.b_p = m.b_p();
  const pb::WheelParams* wheels[kNumWheels] = {&m.lf(), &m.rf(), &m.lr(), &m.rr()};
  for (int w = 0; w < kNumWheels; ++w) {
    const pb::WheelParams& s = *wheels[w];
    WheelParams& d = p.wheel[w];
    d.z_offset = s.z_offset();
    d.spring_stiffness = s.spring_stiffness();
    d.damper_coefficient = s.damper_coefficient();
    d.free_length = s.free_length();
    d.radius = s.radius();
    d.cornering_stiffness = s.cornering_stiffness();
    d.bump_stop_length = s.bump_stop_length();
    d.bump_stop_stiffness = s.bump_stop_stiffness();
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
  p.yaw_mode = ToYawMode(m.yaw_mode());
  p.tire_law = ToTireLaw(m.tire_law());
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
  DeriveParams(p);
  return p;
}

pb::VehicleParams ParseVehicleParams(const std::string& text, bool json,
                                     const std::string& source_name,
                                     const pb::VehicleParams& base) {
  pb::VehicleParams update;
  if (json) {
    gp::util::JsonParseOptions options;
    options.ignore_unknown_fields = false;
    const auto status = gp::util::JsonStringToMessage(text, &update, options);
    if (!status.ok()) {
      throw ParamsError(source_name + ": not valid vehicle parameters JSON: " +
                        std::string(status.message()));
    }
  } else {
    gp::TextFormat::Parser parser;
    CollectErrors errors;
    parser.RecordErrorsTo(&errors);
    if (!parser.ParseFromString(text, &update)) {
      throw ParamsError(source_name + ": " +
                        (errors.text.empty() ? std::string("cannot parse") : errors.text));
    }
  }
  pb::VehicleParams merged = MergeVehicleParams(base, update);
  const std::vector<ParamIssue> issues = ValidateVehicleParams(merged);
  if (!issues.empty()) throw ParamsError(source_name + ": " + FormatIssues(issues));
  return merged;
}

pb::VehicleParams LoadVehicleParamsFile(const std::filesystem::path& path,
                                        const pb::VehicleParams& base) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ParamsError(path.string() + ": cannot open the vehicle parameter file");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw ParamsError(path.string() + ": read error");
  const bool json = path.extension() == ".json";
  return ParseVehicleParams(ss.str(), json, path.string(), base);
}

std::string DumpVehicleParamsText(const pb::VehicleParams& msg) {
  std::string body;
  gp::TextFormat::Printer printer;
  printer.SetUseShortRepeatedPrimitives(true);
  printer.PrintToString(msg, &body);
  return "# vdyn vehicle parameters (protobuf text format, vdyn.pb.VehicleParams).\n"
         "# SI units; field meanings in proto/vdyn/vehicle_params.proto and docs/model.md.\n"
         "# Pass back with --vehicle FILE; a file may list only the fields it changes.\n" +
         body;
}

}  // namespace vdyn
