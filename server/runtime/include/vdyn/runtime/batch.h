// Batch drives: a maneuver through the simulator as fast as possible, optionally to CSV.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "vdyn/io/csv.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/physics/simulator.h"

namespace vdyn {

struct BatchOptions {
  double duration = 0;   // s of simulated time
  int csv_every = 1;     // write every Nth step
  // Format and write the CSV on a second thread while the simulation steps (the same bytes as
  // on one thread: rows keep their order). Off: everything on the calling thread.
  bool csv_thread = true;
};

struct BatchSummary {
  bool ok = true;
  std::string error;     // why the run stopped early (non-finite state)
  std::int64_t steps = 0;
  double sim_time = 0;   // s
  double wall_time = 0;  // s
  double distance = 0;   // m travelled by T in the XY plane
  double max_speed = 0;  // m/s
  double airborne_time = 0;  // s with all four wheels in the air
  double max_Fp = 0;     // N, largest spring force of any wheel
  double max_wall_penetration = 0;  // m
  std::uint64_t final_hash = 0;
  std::size_t csv_rows = 0;
  std::uint64_t csv_rows_formatted_by_stepper = 0;  // with csv_thread: the share it took (CsvPipe)
};

// Runs `sim` for options.duration with the maneuver as input. The CSV (if any) gets the row of
// every csv_every-th step and, last, the final state. `progress` (if set) is called with the fraction
// done at most ~100 times.
BatchSummary RunBatch(Simulator& sim, const Maneuver& maneuver, const BatchOptions& options,
                      CsvWriter* csv, const std::function<void(double)>& progress = {});

}  // namespace vdyn
