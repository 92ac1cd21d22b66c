#include "vdyn/physics/params.h"

#include <cmath>
#include <limits>

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

void DeriveParams(Params& p) {
  p.wheelbase = p.b + p.c;
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
}

}  // namespace

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
  }
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
