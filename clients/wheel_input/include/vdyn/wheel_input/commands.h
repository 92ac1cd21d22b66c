// vdyn-input's commands, each a function its main calls with the parsed command line (and tests
// call directly): play a maneuver, drive with a wheel or the keyboard, list the devices,
// calibrate a wheel. Each returns the program's exit code: 0 done, 1 transport failure or no
// server, 2 bad input (a maneuver, a mapping file, no usable device); a bad maneuver or mapping
// file throws (ManeuverError, MappingError) for main to report. `stop` ends a command early (the
// program's SIGINT and SIGTERM set it).
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

namespace vdyn::wheel_input {

// The options every command takes (before or after the command's name).
struct CommonOptions {
  std::uint32_t domain = 0, vehicle_id = 1;
  std::string source_id = "vdyn-input";
  std::int32_t strength = 10;
  double rate_hz = 1000.0;
  double wait_s = 10.0;
  bool status = false;
  // The 1 kHz loop's SCHED_FIFO priority where permitted (0: the normal scheduler, the default:
  // under busy-looping hogs SCHED_FIFO did not reduce the watchdog's take-overs; the runs are in
  // bench/README.md, "A starved driver").
  int rt_priority = 0;
};

struct PlayOptions {
  std::string maneuver;          // a CSV file or "demo"
  std::string clock = "server";  // "server" (the vehicle's simulation time) or "wall"
  bool loop = false;
};

struct RigOptions {
  bool keyboard = false;  // the keyboard only (vdyn-input keyboard); else the first wheel found
  std::string mapping;
  int device = -1;
  double range_deg = 0;
  bool no_ffb = false;
  double ffb_gain = 1.0, ffb_cap_nm = 4.0, ffb_peak_nm = 0, ffb_rate_hz = 500, ffb_slew = 200,
         ffb_filter_hz = 40, ffb_damper = 0, ffb_damper_below_kmh = 15, ffb_effect_ms = 100;
  double gears = 6, neutral_brake = 0.3, key_steer_rate = 1.5;
  bool no_window = false;
  std::string screenshot;
  double duration_s = 0;
};

struct CalibrateOptions {
  int device = -1;
  int pedals = -1;
  std::string out;
  double range_deg = 0;
  bool no_ffb_test = false;
  double pedal_dead_zone = 0.02, pedal_gamma = 1.0, steer_dead_zone = 0.0;
  double timeout_s = 300;
};

// vdyn-input play: the maneuver as live input at c.rate_hz until its end (or `stop`), then one
// line on how many of the vehicle's states applied it.
int Play(const CommonOptions& c, const PlayOptions& o, const std::atomic<bool>& stop);
// vdyn-input drive / keyboard: the rig loop until `stop` or o.duration_s.
int Drive(const CommonOptions& c, const RigOptions& o, const std::atomic<bool>& stop);
// vdyn-input list: the devices SDL sees; then, unless `once`, their live values for `seconds`
// (0: until `stop`).
int List(bool once, double seconds, const std::atomic<bool>& stop);
// vdyn-input calibrate: a wheel's mapping file, step by step on the terminal.
int Calibrate(const CalibrateOptions& o, const std::atomic<bool>& stop);

// Why no state or parameters of vehicle c.vehicle_id came, for a person: no server, or servers
// with other vehicles (`others`) and how to drive one of them or add this one.
std::string WhyNoVehicle(const CommonOptions& c, const std::vector<std::uint32_t>& others);

}  // namespace vdyn::wheel_input
