#include "csv_output.h"

#include <array>
#include <charconv>
#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace vdyn {
namespace {

using Getter = double (*)(const StepRecord&);
using WheelGetter = double (*)(const StepRecord&, int);

Eigen::Matrix3d Rwb(const StepRecord& r) { return Orientation(r.state.x).toRotationMatrix(); }
Eigen::Vector3d VelB(const StepRecord& r) { return Rwb(r).transpose() * Velocity(r.state.x); }
Eigen::Vector3d AccB(const StepRecord& r) { return Rwb(r).transpose() * r.derived.a_WT_W; }
double Rpy(const StepRecord& r, int i) { return RollPitchYaw(Orientation(r.state.x))[i]; }

struct Column {
  const char* name;
  Getter get;
};
struct WheelColumn {
  const char* prefix;  // name = prefix + "_" + wheel + "_" + unit
  const char* unit;
  WheelGetter get;
};

// One table is the header and the row: they cannot drift apart.
// clang-format off
const Column kColumns[] = {
  {"t_s",          [](const StepRecord& r) { return r.t; }},
  {"step",         [](const StepRecord& r) { return static_cast<double>(r.step); }},
  {"x_m",          [](const StepRecord& r) { return r.state.x[sx::kP + 0]; }},
  {"y_m",          [](const StepRecord& r) { return r.state.x[sx::kP + 1]; }},
  {"z_m",          [](const StepRecord& r) { return r.state.x[sx::kP + 2]; }},
  {"roll_rad",     [](const StepRecord& r) { return Rpy(r, 0); }},
  {"pitch_rad",    [](const StepRecord& r) { return Rpy(r, 1); }},
  {"yaw_rad",      [](const StepRecord& r) { return Rpy(r, 2); }},
  {"vx_mps",       [](const StepRecord& r) { return VelB(r).x(); }},
  {"vy_mps",       [](const StepRecord& r) { return VelB(r).y(); }},
  {"vz_mps",       [](const StepRecord& r) { return VelB(r).z(); }},
  {"wx_radps",     [](const StepRecord& r) { return r.derived.w_eff_B.x(); }},
  {"wy_radps",     [](const StepRecord& r) { return r.derived.w_eff_B.y(); }},
  {"wz_radps",     [](const StepRecord& r) { return r.derived.w_eff_B.z(); }},
  {"ax_mps2",      [](const StepRecord& r) { return AccB(r).x(); }},
  {"ay_mps2",      [](const StepRecord& r) { return AccB(r).y(); }},
  {"az_mps2",      [](const StepRecord& r) { return AccB(r).z(); }},
  {"dwx_radps2",   [](const StepRecord& r) { return r.derived.dw_B.x(); }},
  {"dwy_radps2",   [](const StepRecord& r) { return r.derived.dw_B.y(); }},
  {"dwz_radps2",   [](const StepRecord& r) { return r.derived.dw_B.z(); }},
  {"vxW_mps",      [](const StepRecord& r) { return r.state.x[sx::kV + 0]; }},
  {"vyW_mps",      [](const StepRecord& r) { return r.state.x[sx::kV + 1]; }},
  {"vzW_mps",      [](const StepRecord& r) { return r.state.x[sx::kV + 2]; }},
  {"axW_mps2",     [](const StepRecord& r) { return r.derived.a_WT_W.x(); }},
  {"ayW_mps2",     [](const StepRecord& r) { return r.derived.a_WT_W.y(); }},
  {"azW_mps2",     [](const StepRecord& r) { return r.derived.a_WT_W.z(); }},
  {"speed_kmh",    [](const StepRecord& r) { return 3.6 * Velocity(r.state.x).norm(); }},
  {"Da_N",         [](const StepRecord& r) { return r.derived.Da; }},
  {"Tsteer_Nm",    [](const StepRecord& r) { return r.derived.steering_torque; }},
  {"Fwall_N",      [](const StepRecord& r) { return r.derived.F_wall_W.norm(); }},
  {"wall_pen_m",   [](const StepRecord& r) { return r.derived.wall_penetration_max; }},
  {"steer_in_rad", [](const StepRecord& r) { return r.input.steer; }},
  {"throttle_in",  [](const StepRecord& r) { return r.input.throttle; }},
  {"brake_in",     [](const StepRecord& r) { return r.input.brake; }},
  {"cruise_on",    [](const StepRecord& r) { return r.input.cruise_on ? 1.0 : 0.0; }},
  {"cruise_set_kmh", [](const StepRecord& r) { return 3.6 * r.input.cruise_speed; }},
  {"cruise_u",     [](const StepRecord& r) { return r.control.cruise_u; }},
  {"throttle",     [](const StepRecord& r) { return r.control.throttle; }},
  {"brake",        [](const StepRecord& r) { return r.control.brake; }},
};
const WheelColumn kWheelColumns[] = {
  {"Fp",    "N",     [](const StepRecord& r, int w) { return r.derived.wheel[w].Fp; }},
  {"Fh",    "N",     [](const StepRecord& r, int w) { return r.derived.wheel[w].Fh; }},
  {"Fb",    "N",     [](const StepRecord& r, int w) { return r.derived.wheel[w].Fb; }},
  {"Fy",    "N",     [](const StepRecord& r, int w) { return r.derived.wheel[w].Fy; }},
  {"Frr",   "N",     [](const StepRecord& r, int w) { return r.derived.wheel[w].Frr; }},
  {"lS",    "m",     [](const StepRecord& r, int w) { return r.derived.wheel[w].lS; }},
  {"lT",    "m",     [](const StepRecord& r, int w) { return r.derived.wheel[w].lT; }},
  {"dlS",   "mps",   [](const StepRecord& r, int w) { return r.derived.wheel[w].lS_rate; }},
  {"contact", "",    [](const StepRecord& r, int w) { return r.derived.wheel[w].contact ? 1.0 : 0.0; }},
  {"gamma", "rad",   [](const StepRecord& r, int w) { return r.derived.wheel[w].gamma; }},
  {"slip",  "rad",   [](const StepRecord& r, int w) { return r.derived.wheel[w].slip_angle; }},
  {"xB",    "m",     [](const StepRecord& r, int w) { return r.derived.wheel[w].p_B_W.x(); }},
  {"yB",    "m",     [](const StepRecord& r, int w) { return r.derived.wheel[w].p_B_W.y(); }},
  {"zB",    "m",     [](const StepRecord& r, int w) { return r.derived.wheel[w].p_B_W.z(); }},
};
// clang-format on

}  // namespace

std::vector<std::string> CsvColumns() {
  std::vector<std::string> names;
  for (const Column& c : kColumns) names.emplace_back(c.name);
  for (int w = 0; w < kNumWheels; ++w) {
    for (const WheelColumn& c : kWheelColumns) {
      std::string n = std::string(c.prefix) + "_" + std::string(kWheelNames[w]);
      if (*c.unit != '\0') n += std::string("_") + c.unit;
      names.push_back(std::move(n));
    }
  }
  return names;
}

CsvWriter::CsvWriter(const std::filesystem::path& path) : path_(path), buffer_(1 << 20) {
  std::error_code ec;
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path(), ec);
  file_ = std::fopen(path.c_str(), "wb");
  if (file_ == nullptr) {
    throw std::runtime_error(path.string() + ": cannot create the CSV file: " +
                             std::strerror(errno));
  }
  std::setvbuf(file_, buffer_.data(), _IOFBF, buffer_.size());
  std::string header;
  for (const std::string& n : CsvColumns()) {
    if (!header.empty()) header += ',';
    header += n;
  }
  header += '\n';
  std::fwrite(header.data(), 1, header.size(), file_);
}

CsvWriter::~CsvWriter() {
  if (file_ != nullptr) std::fclose(file_);
}

void CsvWriter::WriteRow(const StepRecord& r) {
  // Shortest round-trip decimal form (std::to_chars): exact, locale-free and deterministic.
  std::array<char, 64 * (std::size(kColumns) + kNumWheels * std::size(kWheelColumns))> line;
  char* p = line.data();
  char* const end = line.data() + line.size();
  auto put = [&](double v) {
    if (v == 0.0) v = 0.0;  // no "-0"
    p = std::to_chars(p, end, v).ptr;
    *p++ = ',';
  };
  for (const Column& c : kColumns) put(c.get(r));
  for (int w = 0; w < kNumWheels; ++w) {
    for (const WheelColumn& c : kWheelColumns) put(c.get(r, w));
  }
  p[-1] = '\n';
  std::fwrite(line.data(), 1, static_cast<std::size_t>(p - line.data()), file_);
  ++rows_;
}

void CsvWriter::Close() {
  if (file_ == nullptr) return;
  const bool write_error = std::ferror(file_) != 0;
  const bool close_error = std::fclose(file_) != 0;
  file_ = nullptr;
  if (write_error || close_error) {
    throw std::runtime_error(path_.string() + ": writing the CSV failed: " + std::strerror(errno));
  }
}

}  // namespace vdyn
