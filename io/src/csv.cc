#include "vdyn/io/csv.h"

#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string_view>

#include "vdyn/io/shortest_double.h"

namespace vdyn {
namespace {

using State = pb::VehicleState;
using Getter = double (*)(const State&);
using WheelGetter = double (*)(const pb::WheelState&);

double Norm(const pb::Vec3& v) { return std::sqrt(v.x() * v.x() + v.y() * v.y() + v.z() * v.z()); }

struct Column {
  const char* name;
  Getter get;
};
struct WheelColumn {
  const char* prefix;  // name = prefix + "_" + wheel + "_" + unit
  const char* unit;
  WheelGetter get;
};

constexpr std::string_view kWheels[] = {"LF", "RF", "LR", "RR"};

// One table is the header and the row: they cannot drift apart.
// clang-format off
const Column kColumns[] = {
  {"t_s",          [](const State& s) { return static_cast<double>(s.step()) * (static_cast<double>(s.step_ns()) * 1e-9); }},
  {"step",         [](const State& s) { return static_cast<double>(s.step()); }},
  {"x_m",          [](const State& s) { return s.p_wt_w().x(); }},
  {"y_m",          [](const State& s) { return s.p_wt_w().y(); }},
  {"z_m",          [](const State& s) { return s.p_wt_w().z(); }},
  {"roll_rad",     [](const State& s) { return s.rpy().x(); }},
  {"pitch_rad",    [](const State& s) { return s.rpy().y(); }},
  {"yaw_rad",      [](const State& s) { return s.rpy().z(); }},
  {"vx_mps",       [](const State& s) { return s.v_wt_b().x(); }},
  {"vy_mps",       [](const State& s) { return s.v_wt_b().y(); }},
  {"vz_mps",       [](const State& s) { return s.v_wt_b().z(); }},
  {"wx_radps",     [](const State& s) { return s.w_wb_b().x(); }},
  {"wy_radps",     [](const State& s) { return s.w_wb_b().y(); }},
  {"wz_radps",     [](const State& s) { return s.w_wb_b().z(); }},
  {"ax_mps2",      [](const State& s) { return s.a_wt_b().x(); }},
  {"ay_mps2",      [](const State& s) { return s.a_wt_b().y(); }},
  {"az_mps2",      [](const State& s) { return s.a_wt_b().z(); }},
  {"dwx_radps2",   [](const State& s) { return s.dw_wb_b().x(); }},
  {"dwy_radps2",   [](const State& s) { return s.dw_wb_b().y(); }},
  {"dwz_radps2",   [](const State& s) { return s.dw_wb_b().z(); }},
  {"vxW_mps",      [](const State& s) { return s.v_wt_w().x(); }},
  {"vyW_mps",      [](const State& s) { return s.v_wt_w().y(); }},
  {"vzW_mps",      [](const State& s) { return s.v_wt_w().z(); }},
  {"axW_mps2",     [](const State& s) { return s.a_wt_w().x(); }},
  {"ayW_mps2",     [](const State& s) { return s.a_wt_w().y(); }},
  {"azW_mps2",     [](const State& s) { return s.a_wt_w().z(); }},
  {"speed_kmh",    [](const State& s) { return s.speed_kmh(); }},
  {"Da_N",         [](const State& s) { return s.da(); }},
  {"Tsteer_Nm",    [](const State& s) { return s.steering_torque(); }},
  {"Fwall_N",      [](const State& s) { return Norm(s.f_wall_w()); }},
  {"wall_pen_m",   [](const State& s) { return s.wall_pen(); }},
  {"steer_in_rad", [](const State& s) { return s.input().steer(); }},
  {"throttle_in",  [](const State& s) { return s.input().throttle(); }},
  {"brake_in",     [](const State& s) { return s.input().brake(); }},
  {"cruise_on",    [](const State& s) { return s.input().cruise_on() ? 1.0 : 0.0; }},
  {"cruise_set_kmh", [](const State& s) { return s.input().cruise_set_kmh(); }},
  {"cruise_u",     [](const State& s) { return s.control().cruise_u(); }},
  {"throttle",     [](const State& s) { return s.control().throttle(); }},
  {"brake",        [](const State& s) { return s.control().brake(); }},
};
const WheelColumn kWheelColumns[] = {
  {"Fp",    "N",     [](const pb::WheelState& w) { return w.fp(); }},
  {"Fh",    "N",     [](const pb::WheelState& w) { return w.fh(); }},
  {"Fb",    "N",     [](const pb::WheelState& w) { return w.fb(); }},
  {"Fy",    "N",     [](const pb::WheelState& w) { return w.fy(); }},
  {"Frr",   "N",     [](const pb::WheelState& w) { return w.frr(); }},
  {"lS",    "m",     [](const pb::WheelState& w) { return w.ls(); }},
  {"lT",    "m",     [](const pb::WheelState& w) { return w.lt(); }},
  {"dlS",   "mps",   [](const pb::WheelState& w) { return w.dls(); }},
  {"contact", "",    [](const pb::WheelState& w) { return w.contact() ? 1.0 : 0.0; }},
  {"gamma", "rad",   [](const pb::WheelState& w) { return w.gamma(); }},
  {"slip",  "rad",   [](const pb::WheelState& w) { return w.slip(); }},
  {"xB",    "m",     [](const pb::WheelState& w) { return w.p_b_w().x(); }},
  {"yB",    "m",     [](const pb::WheelState& w) { return w.p_b_w().y(); }},
  {"zB",    "m",     [](const pb::WheelState& w) { return w.p_b_w().z(); }},
};
// Appended for the full model (issue 8), after every column above: the columns a reader of an
// older file knows keep their places.
const Column kExtraColumns[] = {
  {"model",          [](const State& s) { return static_cast<double>(s.model()); }},
  {"steer_mode_in",  [](const State& s) { return static_cast<double>(s.input().steer_mode()); }},
  {"clutch_in",      [](const State& s) { return s.input().clutch(); }},
  {"handbrake_in",   [](const State& s) { return s.input().handbrake(); }},
  {"gear_in",        [](const State& s) { return static_cast<double>(s.input().gear()); }},
  {"Tsteer_align_Nm", [](const State& s) { return s.steering().torque_aligning(); }},
  {"Tsteer_trail_Nm", [](const State& s) { return s.steering().torque_trail(); }},
  {"Tsteer_fric_Nm", [](const State& s) { return s.steering().torque_friction(); }},
  {"Tsteer_damp_Nm", [](const State& s) { return s.steering().torque_damping(); }},
  {"Tsteer_stop_Nm", [](const State& s) { return s.steering().torque_end_stop(); }},
  {"Tdriver_Nm",     [](const State& s) { return s.steering().driver_torque(); }},
  {"hw_angle_rad",   [](const State& s) { return s.steering().hand_wheel_angle(); }},
  {"hw_rate_radps",  [](const State& s) { return s.steering().hand_wheel_rate(); }},
  {"hands_on",       [](const State& s) { return s.steering().hands_on() ? 1.0 : 0.0; }},
  {"engine_rpm",     [](const State& s) { return s.drivetrain().engine_rpm(); }},
  {"engine_torque_Nm", [](const State& s) { return s.drivetrain().engine_torque(); }},
  {"gear",           [](const State& s) { return static_cast<double>(s.drivetrain().gear()); }},
  {"shifting",       [](const State& s) { return s.drivetrain().shifting() ? 1.0 : 0.0; }},
  {"clutch_torque_Nm", [](const State& s) { return s.drivetrain().clutch_torque(); }},
  {"clutch_slip_rpm", [](const State& s) { return s.drivetrain().clutch_slip_rpm(); }},
  {"engine_throttle", [](const State& s) { return s.drivetrain().throttle(); }},
  {"tc_factor",      [](const State& s) { return s.drivetrain().tc_factor(); }},
};
const WheelColumn kExtraWheelColumns[] = {
  {"omega", "radps", [](const pb::WheelState& w) { return w.omega(); }},
  {"kappa", "",      [](const pb::WheelState& w) { return w.slip_ratio(); }},
  {"kappa_t", "",    [](const pb::WheelState& w) { return w.slip_ratio_t(); }},
  {"alpha_t", "rad", [](const pb::WheelState& w) { return w.slip_angle_t(); }},
  {"Fx",    "N",     [](const pb::WheelState& w) { return w.fx(); }},
  {"Mz",    "Nm",    [](const pb::WheelState& w) { return w.mz(); }},
  {"Tdrive", "Nm",   [](const pb::WheelState& w) { return w.drive_torque(); }},
  {"Tbrake", "Nm",   [](const pb::WheelState& w) { return w.brake_torque(); }},
  {"vlong", "mps",   [](const pb::WheelState& w) { return w.v_long(); }},
  {"abs",   "",      [](const pb::WheelState& w) { return w.abs_factor(); }},
  {"kerb",  "",      [](const pb::WheelState& w) { return w.kerb() ? 1.0 : 0.0; }},
};
// Appended for the tyre laws' inputs and outputs (issue 34), after every column above.
const WheelColumn kTireWheelColumns[] = {
  {"kappaLaw", "",     [](const pb::WheelState& w) { return w.kappa_law(); }},
  {"alphaLaw", "rad",  [](const pb::WheelState& w) { return w.alpha_law(); }},
  {"camber", "rad",    [](const pb::WheelState& w) { return w.camber(); }},
  {"pressure", "Pa",   [](const pb::WheelState& w) { return w.pressure(); }},
  {"Mx",    "Nm",      [](const pb::WheelState& w) { return w.mx(); }},
  {"My",    "Nm",      [](const pb::WheelState& w) { return w.my(); }},
};
// clang-format on

constexpr std::size_t kNumValues = std::size(kColumns) + 4 * std::size(kWheelColumns) +
                                   std::size(kExtraColumns) + 4 * std::size(kExtraWheelColumns) +
                                   4 * std::size(kTireWheelColumns);

void AddWheelNames(const WheelColumn* cols, std::size_t n, std::vector<std::string>& names) {
  for (std::string_view wheel : kWheels) {
    for (std::size_t i = 0; i < n; ++i) {
      std::string name = std::string(cols[i].prefix) + "_" + std::string(wheel);
      if (*cols[i].unit != '\0') name += std::string("_") + cols[i].unit;
      names.push_back(std::move(name));
    }
  }
}

const pb::WheelState& WheelOf(const State& s, int w) {
  return w < s.wheels_size() ? s.wheels(w) : pb::WheelState::default_instance();
}

}  // namespace

std::vector<std::string> CsvColumns() {
  std::vector<std::string> names;
  for (const Column& c : kColumns) names.emplace_back(c.name);
  AddWheelNames(kWheelColumns, std::size(kWheelColumns), names);
  for (const Column& c : kExtraColumns) names.emplace_back(c.name);
  AddWheelNames(kExtraWheelColumns, std::size(kExtraWheelColumns), names);
  AddWheelNames(kTireWheelColumns, std::size(kTireWheelColumns), names);
  return names;
}

void CsvRowValues(const State& s, std::vector<double>& out) {
  out.clear();
  for (const Column& c : kColumns) out.push_back(c.get(s));
  for (int w = 0; w < 4; ++w) {
    for (const WheelColumn& c : kWheelColumns) out.push_back(c.get(WheelOf(s, w)));
  }
  for (const Column& c : kExtraColumns) out.push_back(c.get(s));
  for (int w = 0; w < 4; ++w) {
    for (const WheelColumn& c : kExtraWheelColumns) out.push_back(c.get(WheelOf(s, w)));
  }
  for (int w = 0; w < 4; ++w) {
    for (const WheelColumn& c : kTireWheelColumns) out.push_back(c.get(WheelOf(s, w)));
  }
}

CsvWriter::CsvWriter(const std::filesystem::path& path)
    : path_(path), buffer_(1 << 20), row_(CsvRowMaxBytes()) {
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

char* CsvNumber(char* p, char* end, double v) {
  if (v == 0.0) v = 0.0;  // no "-0"
  if (end - p >= kShortestDoubleBytes) return WriteShortestDouble(p, v);
  return std::to_chars(p, end, v).ptr;
}

std::size_t CsvRowMaxBytes() { return kShortestDoubleBytes * kNumValues; }

std::size_t FormatCsvRow(const State& s, char* out) {
  // Shortest round-trip decimal form (as std::to_chars writes it): exact, locale-free, deterministic.
  char* p = out;
  char* const end = out + CsvRowMaxBytes();
  auto put = [&](double v) {
    p = CsvNumber(p, end, v);
    *p++ = ',';
  };
  for (const Column& c : kColumns) put(c.get(s));
  for (int w = 0; w < 4; ++w) {
    for (const WheelColumn& c : kWheelColumns) put(c.get(WheelOf(s, w)));
  }
  for (const Column& c : kExtraColumns) put(c.get(s));
  for (int w = 0; w < 4; ++w) {
    for (const WheelColumn& c : kExtraWheelColumns) put(c.get(WheelOf(s, w)));
  }
  for (int w = 0; w < 4; ++w) {
    for (const WheelColumn& c : kTireWheelColumns) put(c.get(WheelOf(s, w)));
  }
  p[-1] = '\n';
  return static_cast<std::size_t>(p - out);
}

void CsvWriter::WriteRow(const State& s) {
  WriteFormattedRow(row_.data(), FormatCsvRow(s, row_.data()));
}

void CsvWriter::WriteFormattedRow(const char* row, std::size_t length) {
  std::fwrite(row, 1, length, file_);
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
