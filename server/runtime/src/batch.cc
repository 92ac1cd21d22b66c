#include "vdyn/runtime/batch.h"

#include <chrono>
#include <cmath>
#include <optional>

#include "vdyn/base/text.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/runtime/csv_pipe.h"

namespace vdyn {

BatchSummary RunBatch(Simulator& sim, const Maneuver& maneuver, const BatchOptions& options,
                      CsvWriter* csv, const std::function<void(double)>& progress) {
  BatchSummary s;
  const auto wall_start = std::chrono::steady_clock::now();
  const auto n_steps = static_cast<std::int64_t>(std::llround(options.duration / sim.h()));
  const std::int64_t progress_every = std::max<std::int64_t>(1, n_steps / 100);
  const int every = std::max(1, options.csv_every);
  Eigen::Vector3d last_p = Position(sim.state().x);
  std::optional<CsvRowFormatter> serial;
  std::optional<CsvPipe> pipe;
  if (csv != nullptr && options.csv_thread) {
    pipe.emplace(*csv, sim.step_ns());
  } else if (csv != nullptr) {
    serial.emplace(sim.step_ns());
  }
  auto write_row = [&](const StepRecord& r) {
    if (pipe) {
      pipe->Push(r);
    } else {
      serial->Write(r, *csv);
    }
  };

  for (std::int64_t i = 0; i < n_steps; ++i) {
    sim.SetInput(FromManeuver(maneuver.At(sim.time())));
    if (const StepStatus status = sim.Step(); status != StepStatus::kOk) {
      s.ok = false;
      s.error = std::string("the vehicle stopped at t = ") + base::FormatFixed(sim.time(), 3) +
                " s (step " + std::to_string(sim.state().step) + "): " + StepStatusText(status) +
                (status == StepStatus::kRunaway ? ": the parameters drive the model past what it "
                                                  "resolves"
                                                : "") +
                "; the run stopped there and the last state before it was kept (docs/model.md)";
      break;
    }
    const StepRecord& r = sim.last_step();
    if (csv != nullptr && r.step % every == 0) write_row(r);
    bool airborne = true;
    for (const WheelOutputs& w : r.derived.wheel) {
      airborne = airborne && !w.contact;
      s.max_Fp = std::max(s.max_Fp, w.Fp);
    }
    if (airborne) s.airborne_time += sim.h();
    s.max_wall_penetration = std::max(s.max_wall_penetration, r.derived.wall_penetration_max);
    const Eigen::Vector3d p = Position(sim.state().x);
    s.distance += (p - last_p).head<2>().norm();
    last_p = p;
    s.max_speed = std::max(s.max_speed, Velocity(sim.state().x).norm());
    ++s.steps;
    if (progress && (i + 1) % progress_every == 0) {
      progress(static_cast<double>(i + 1) / static_cast<double>(n_steps));
    }
  }
  if (csv != nullptr && s.ok) {
    // The final state, with its derived quantities, closes the record.
    StepRecord last;
    sim.SetInput(FromManeuver(maneuver.At(sim.time())));
    last.step = sim.state().step;
    last.t = sim.time();
    last.state = sim.state();
    last.input = sim.input();
    sim.Forward(last.derived, &last.control);
    last.hash_after = StateHash(sim.state());
    write_row(last);
  }
  if (pipe) {
    pipe->Finish();
    s.csv_rows_formatted_by_stepper = pipe->rows_formatted_by_pusher();
  }
  s.sim_time = sim.time();
  s.final_hash = StateHash(sim.state());
  s.csv_rows = csv != nullptr ? csv->rows() : 0;
  s.wall_time =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  return s;
}

}  // namespace vdyn
