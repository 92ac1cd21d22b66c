// States as columns: every state becomes one row of the vehicle CSV's columns (vdyn/io/csv.h, the
// same names, units and order as `vdyn-server --batch` and `vdyn-recorder export`), plus the
// integers a double cannot hold exactly (step, state hash, simulation time).
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "vdyn/state.pb.h"

namespace vdyn::python {

// The CSV's column names (computed once).
const std::vector<std::string>& StateColumns();

// Rows of states of one vehicle, appended in arrival order.
struct StateTable {
  std::vector<double> values;  // rows x StateColumns().size(), row-major
  std::vector<std::uint64_t> step;
  std::vector<std::uint64_t> state_hash;
  std::vector<std::int64_t> sim_time_ns;
  std::vector<std::uint64_t> log_time_ns;  // recordings: when the recorder took it (else empty)
  std::uint64_t malformed = 0;             // recordings: states skipped because they did not parse
  // Recordings: the server starts that stepped the vehicle, one line each in the order they came
  // ("server 'vdyn' start 0x...: steps 0..3999, 4000 states"); their rows follow one another.
  std::vector<std::string> runs;

  void Append(const pb::VehicleState& s);
  std::size_t rows() const { return step.size(); }
  void Reserve(std::size_t n);
  void Extend(const StateTable& more);  // appends its rows
  // Sorts the rows by step (a recording's states arrive in the order the recorder took them).
  void SortByStep();
};

// Exceptions the module turns into vdyn.TimeoutError and vdyn.RefusedError (vdyn/_errors.py).
class TimeoutError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
class RefusedError : public std::runtime_error {
 public:
  RefusedError(const std::string& what, std::string reason)
      : std::runtime_error(what), reason_(std::move(reason)) {}
  const std::string& reason() const { return reason_; }

 private:
  std::string reason_;
};

}  // namespace vdyn::python
