#include "state_columns.h"

#include <algorithm>
#include <numeric>

#include "vdyn/io/csv.h"

namespace vdyn::python {

const std::vector<std::string>& StateColumns() {
  static const std::vector<std::string> columns = CsvColumns();
  return columns;
}

void StateTable::Reserve(std::size_t n) {
  values.reserve(n * StateColumns().size());
  step.reserve(n);
  state_hash.reserve(n);
  sim_time_ns.reserve(n);
}

void StateTable::Append(const pb::VehicleState& s) {
  thread_local std::vector<double> row;
  CsvRowValues(s, row);
  values.insert(values.end(), row.begin(), row.end());
  step.push_back(s.step());
  state_hash.push_back(s.state_hash());
  sim_time_ns.push_back(s.sim_time_ns());
}

void StateTable::Extend(const StateTable& more) {
  values.insert(values.end(), more.values.begin(), more.values.end());
  step.insert(step.end(), more.step.begin(), more.step.end());
  state_hash.insert(state_hash.end(), more.state_hash.begin(), more.state_hash.end());
  sim_time_ns.insert(sim_time_ns.end(), more.sim_time_ns.begin(), more.sim_time_ns.end());
  log_time_ns.insert(log_time_ns.end(), more.log_time_ns.begin(), more.log_time_ns.end());
}

void StateTable::SortByStep() {
  if (std::is_sorted(step.begin(), step.end())) return;
  const std::size_t n = rows(), c = StateColumns().size();
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return step[a] < step[b]; });
  StateTable sorted;
  sorted.Reserve(n);
  for (std::size_t i : order) {
    sorted.values.insert(sorted.values.end(), values.begin() + static_cast<std::ptrdiff_t>(i * c),
                         values.begin() + static_cast<std::ptrdiff_t>((i + 1) * c));
    sorted.step.push_back(step[i]);
    sorted.state_hash.push_back(state_hash[i]);
    sorted.sim_time_ns.push_back(sim_time_ns[i]);
    if (!log_time_ns.empty()) sorted.log_time_ns.push_back(log_time_ns[i]);
  }
  *this = std::move(sorted);
}

}  // namespace vdyn::python
