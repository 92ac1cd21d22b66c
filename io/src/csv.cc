#include "vdyn/io/csv.h"

#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string_view>

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
// clang-format on

constexpr std::size_t kNumValues = std::size(kColumns) + 4 * std::size(kWheelColumns);

const pb::WheelState& WheelOf(const State& s, int w) {
  return w < s.wheels_size() ? s.wheels(w) : pb::WheelState::default_instance();
}

}  // namespace

std::vector<std::string> CsvColumns() {
  std::vector<std::string> names;
  for (const Column& c : kColumns) names.emplace_back(c.name);
  for (std::string_view wheel : kWheels) {
    for (const WheelColumn& c : kWheelColumns) {
      std::string n = std::string(c.prefix) + "_" + std::string(wheel);
      if (*c.unit != '\0') n += std::string("_") + c.unit;
      names.push_back(std::move(n));
    }
  }
  return names;
}

void CsvRowValues(const State& s, std::vector<double>& out) {
  out.clear();
  for (const Column& c : kColumns) out.push_back(c.get(s));
  for (int w = 0; w < 4; ++w) {
    for (const WheelColumn& c : kWheelColumns) out.push_back(c.get(WheelOf(s, w)));
  }
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

void CsvWriter::WriteRow(const State& s) {
  // Shortest round-trip decimal form (std::to_chars): exact, locale-free and deterministic.
  std::array<char, 64 * kNumValues> line;
  char* p = line.data();
  char* const end = line.data() + line.size();
  auto put = [&](double v) {
    if (v == 0.0) v = 0.0;  // no "-0"
    p = std::to_chars(p, end, v).ptr;
    *p++ = ',';
  };
  for (const Column& c : kColumns) put(c.get(s));
  for (int w = 0; w < 4; ++w) {
    for (const WheelColumn& c : kWheelColumns) put(c.get(WheelOf(s, w)));
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
