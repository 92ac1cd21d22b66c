#include "vdyn/io/maneuver.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

#include "vdyn/base/limits.h"
#include "vdyn/base/text.h"

namespace vdyn {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
const char* const kManeuverColumns[] = {"t_s", "steer_deg", "throttle", "brake", "cruise_kmh"};
constexpr int kNumColumns = 5;

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

std::vector<std::string_view> Split(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    out.push_back(Trim(line.substr(start, comma == std::string_view::npos ? line.npos
                                                                           : comma - start)));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return out;
}

}  // namespace

Maneuver Maneuver::Parse(const std::string& text, const std::string& source) {
  std::istringstream in(std::string(base::StripBom(text)));
  return Read(in, source);
}

Maneuver Maneuver::Read(std::istream& in, const std::string& source) {
  Maneuver m;
  int column_of[kNumColumns] = {-1, -1, -1, -1, -1};
  std::size_t n_fields = 0;
  bool have_header = false;
  std::string raw;
  std::int64_t line_no = 0;
  auto fail = [&](const std::string& what) -> ManeuverError {
    return ManeuverError(source + ":" + std::to_string(line_no) + ": " + what);
  };
  while (std::getline(in, raw)) {
    ++line_no;
    const std::string_view line = Trim(line_no == 1 ? base::StripBom(raw) : raw);
    if (line.empty() || line.front() == '#') continue;
    const std::vector<std::string_view> fields = Split(line);
    if (!have_header) {
      for (std::size_t i = 0; i < fields.size(); ++i) {
        const auto* it = std::find(std::begin(kManeuverColumns), std::end(kManeuverColumns), fields[i]);
        if (it == std::end(kManeuverColumns)) {
          throw fail("unknown column '" + std::string(fields[i]) +
                     "' (the header is t_s,steer_deg,throttle,brake,cruise_kmh)");
        }
        const auto c = static_cast<int>(it - std::begin(kManeuverColumns));
        if (column_of[c] >= 0) throw fail("column '" + std::string(fields[i]) + "' appears twice");
        column_of[c] = static_cast<int>(i);
      }
      for (int c = 0; c < 4; ++c) {
        if (column_of[c] < 0) {
          throw fail("missing column '" + std::string(kManeuverColumns[c]) +
                     "' (the header is t_s,steer_deg,throttle,brake,cruise_kmh)");
        }
      }
      n_fields = fields.size();
      have_header = true;
      continue;
    }
    if (fields.size() != n_fields) {
      throw fail("expected " + std::to_string(n_fields) + " fields, found " +
                 std::to_string(fields.size()));
    }
    double v[kNumColumns] = {0, 0, 0, 0, 0};
    bool present[kNumColumns] = {false, false, false, false, false};
    for (int c = 0; c < kNumColumns; ++c) {
      if (column_of[c] < 0) continue;
      const std::string_view f = fields[static_cast<std::size_t>(column_of[c])];
      if (f.empty()) {
        if (c == 4) continue;  // empty cruise_kmh: speed control off
        throw fail("column '" + std::string(kManeuverColumns[c]) + "': empty value");
      }
      const std::optional<double> parsed = base::ParseNumber(f);
      if (!parsed) {
        throw fail("column '" + std::string(kManeuverColumns[c]) + "': '" + base::Quote(f, 40) +
                   "' is not a finite number");
      }
      v[c] = *parsed;
      present[c] = true;
    }
    auto range = [&](int c, double lo, double hi) {
      if (v[c] < lo || v[c] > hi) {
        throw fail("column '" + std::string(kManeuverColumns[c]) + "': " + base::FormatNumber(v[c]) +
                   " is outside [" + base::FormatNumber(lo) + ", " + base::FormatNumber(hi) + "]");
      }
    };
    range(0, 0.0, 1e7);
    range(1, -85.0, 85.0);  // below the steering limit every input path accepts (85 deg < 1.5 rad)
    range(2, limits::kThrottle.lo, limits::kThrottle.hi);
    range(3, limits::kBrake.lo, limits::kBrake.hi);
    if (present[4]) range(4, limits::kCruiseSetKmh.lo, limits::kCruiseSetKmh.hi);
    if (!m.rows_.empty() && !(v[0] > m.rows_.back().t)) {
      throw fail("column 't_s': " + base::FormatNumber(v[0]) + " does not increase (previous row " +
                 base::FormatNumber(m.rows_.back().t) + ")");
    }
    if (m.rows_.size() == limits::kMaxManeuverRows) {
      throw fail("more than " + std::to_string(limits::kMaxManeuverRows) +
                 " rows, the most a maneuver may hold (docs/formats.md): thin it out (rows are "
                 "interpolated) or split the drive");
    }
    ManeuverRow row;
    row.t = v[0];
    row.steer = v[1] * kDeg;
    row.throttle = v[2];
    row.brake = v[3];
    if (present[4]) row.cruise_speed = v[4] / 3.6;
    m.rows_.push_back(row);
  }
  if (in.bad()) throw ManeuverError(source + ": reading failed at line " + std::to_string(line_no));
  if (!have_header) throw ManeuverError(source + ": empty maneuver (no header, no rows)");
  if (m.rows_.empty()) throw ManeuverError(source + ": the maneuver has a header but no rows");
  return m;
}

Maneuver Maneuver::Load(const std::filesystem::path& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    throw ManeuverError(path.string() + ": is a directory, not a maneuver file");
  }
  if (!std::filesystem::exists(path, ec)) {
    throw ManeuverError(path.string() + ": no such maneuver file (or 'demo' for the built-in one)");
  }
  // Refused before anything is read when larger than a maneuver may be; then read line by line.
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (!ec && size > limits::kMaxManeuverBytes) {
    throw ManeuverError(path.string() + ": " + std::to_string(size) +
                        " bytes, more than a maneuver file may hold (" +
                        std::to_string(limits::kMaxManeuverBytes) +
                        " bytes, docs/formats.md): thin it out (rows are interpolated) or split "
                        "the drive");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ManeuverError(path.string() + ": cannot open the maneuver file");
  return Read(in, path.string());
}

Maneuver Maneuver::Named(const std::string& name_or_path) {
  return name_or_path == "demo" ? Parse(DemoManeuverCsv(), "demo") : Load(name_or_path);
}

ManeuverInput Maneuver::At(double t) const {
  // First row whose time is greater than t.
  const auto next = std::upper_bound(rows_.begin(), rows_.end(), t,
                                     [](double tt, const ManeuverRow& r) { return tt < r.t; });
  ManeuverInput in;
  auto set = [&in](const ManeuverRow& r) {
    in.steer = r.steer;
    in.throttle = r.throttle;
    in.brake = r.brake;
    in.cruise_on = r.cruise_speed.has_value();
    in.cruise_speed = r.cruise_speed.value_or(0.0);
  };
  if (next == rows_.begin()) {
    set(rows_.front());
    return in;
  }
  const ManeuverRow& a = *(next - 1);
  set(a);
  if (next == rows_.end()) return in;
  const ManeuverRow& b = *next;
  const double s = (t - a.t) / (b.t - a.t);
  in.steer = a.steer + s * (b.steer - a.steer);
  in.throttle = a.throttle + s * (b.throttle - a.throttle);
  in.brake = a.brake + s * (b.brake - a.brake);
  if (a.cruise_speed && b.cruise_speed) {
    in.cruise_speed = *a.cruise_speed + s * (*b.cruise_speed - *a.cruise_speed);
  }
  return in;
}

const std::string& DemoManeuverCsv() {
  // On `facility` from the road's west end (x = -250 m) heading east: cruise at 50 km/h over the
  // speed bumps (x = -180..-140), the washboard (-100..-80), the one-sided bump (-40) and jump
  // ramp A (x = 40), then a step steer to the left and its mirror to the right, which brings the
  // heading back: the car moves over about 1 m and stays on the 8 m wide road (every wheel on
  // asphalt, tests/test_validation.cc), and a full stop at x ~ 195 m, 67 m before the road ends.
  // The steps come just before the stop, so that a heading left by late input (a watchdog that
  // held the steering) carries the car a short way only. (Before, one 3 degree step held 4 s
  // turned the car 53 degrees off the road onto the grass.)
  static const std::string csv =
      "t_s,steer_deg,throttle,brake,cruise_kmh\n"
      "# accelerate on the automatic speed control along the test road\n"
      "0,0,0,0,50\n"
      "# over the speed bumps, the washboard, the one-sided bump and jump ramp A (t ~ 23 s)\n"
      "31.3,0,0,0,50\n"
      "# step steer: 1.5 degrees to the left within 0.1 s, held 0.6 s (the yaw rate settles in\n"
      "# about 0.3 s); then 1.5 degrees to the right, held as long; then straight\n"
      "31.4,1.5,0,0,50\n"
      "32,1.5,0,0,50\n"
      "32.2,-1.5,0,0,50\n"
      "32.8,-1.5,0,0,50\n"
      "32.9,0,0,0,50\n"
      "# full stop: speed control off, full brake\n"
      "33,0,0,0,\n"
      "33.1,0,0,1,\n"
      "40,0,0,1,\n";
  return csv;
}

}  // namespace vdyn
