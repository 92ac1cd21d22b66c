// Maneuvers: driver input over time from a CSV file (t_s,steer_deg,throttle,brake,cruise_kmh).
// No physics: the batch runner and every client (vdyn-input's playback) read the same files.
#pragma once

#include <filesystem>
#include <iosfwd>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace vdyn {

class ManeuverError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// What a maneuver asks for at one time, SI (the same fields as the physics' DriverInput).
struct ManeuverInput {
  double steer = 0;         // front road-wheel angle, rad, positive to the left
  double throttle = 0;      // [-1, 1]
  double brake = 0;         // [0, 1]
  bool cruise_on = false;
  double cruise_speed = 0;  // m/s
};

struct ManeuverRow {
  double t = 0;                        // s
  double steer = 0;                    // rad (the file holds degrees)
  double throttle = 0;                 // [-1, 1]
  double brake = 0;                    // [0, 1]
  std::optional<double> cruise_speed;  // m/s (the file holds km/h); empty: off
};

class Maneuver {
 public:
  // Parses CSV text; `source` names it in errors ("file.csv:7: column 'brake': ...").
  static Maneuver Parse(const std::string& text, const std::string& source);
  // Reads a file line by line (or says why not: missing, a directory, unreadable, larger than
  // limits::kMaxManeuverBytes); at most limits::kMaxManeuverRows rows.
  static Maneuver Load(const std::filesystem::path& path);
  // "demo" or a file.
  static Maneuver Named(const std::string& name_or_path);

  // Input at time t: steer, throttle, brake and cruise speed linear between rows; cruise on/off
  // taken from the row at or before t. Before the first row: the first row; after the last: the last.
  ManeuverInput At(double t) const;

  double end_time() const { return rows_.back().t; }
  const std::vector<ManeuverRow>& rows() const { return rows_; }

 private:
  // Parses lines until the end of `in`; a leading byte-order mark is skipped.
  static Maneuver Read(std::istream& in, const std::string& source);

  std::vector<ManeuverRow> rows_;
};

// The built-in demo drive on `facility` (CSV text, as a file would hold it).
const std::string& DemoManeuverCsv();

}  // namespace vdyn
