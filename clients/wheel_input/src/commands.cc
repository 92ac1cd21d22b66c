#include "vdyn/wheel_input/commands.h"

#include <cstdint>

#include "command_support.h"
#include "vdyn/base/scheduling.h"

namespace vdyn::wheel_input {

std::string SetUpLoopScheduling(const CommonOptions& c) {
  if (c.rt_priority == 0) return "SCHED_OTHER (--rt-priority 0)";
  return base::SetUpRealtimeScheduling(c.rt_priority);
}

base::Nanos LoopPeriod(double hz) {
  return base::Nanos{static_cast<std::int64_t>(1e9 / hz)};
}

std::string WhyNoVehicle(const CommonOptions& c, const std::vector<std::uint32_t>& others) {
  if (others.empty()) return "is vdyn-server running?";
  std::string ids;
  for (const std::uint32_t id : others) {
    if (!ids.empty()) ids += ',';
    ids += std::to_string(id);
  }
  return std::string("vdyn-server there has ") + (others.size() == 1 ? "vehicle " : "vehicles ") +
         ids + ": drive " + (others.size() == 1 ? "it" : "one") + " with --vehicle-id " +
         std::to_string(others.front()) + ", or start vdyn-server with --vehicle-ids " + ids + "," +
         std::to_string(c.vehicle_id);
}

}  // namespace vdyn::wheel_input
