#include "vdyn/foxglove/clock.h"

#include <algorithm>

namespace vdyn::foxglove {

namespace {
std::uint64_t NonNegative(std::int64_t ns) { return static_cast<std::uint64_t>(std::max<std::int64_t>(ns, 0)); }
}  // namespace

std::uint64_t BridgeClock::OnState(const std::string& server_id, std::uint64_t incarnation,
                                   std::int64_t sim_time_ns, base::MonoTime now, bool* changed) {
  const bool same_server = set_ && server_id == server_id_;
  const bool take = !set_ || (same_server && incarnation != incarnation_) ||
                    (!same_server && now - heard_ > silence_);
  if (changed != nullptr) *changed = take;
  if (take) {
    set_ = true;
    server_id_ = server_id;
    incarnation_ = incarnation;
  } else if (!same_server) {
    return ns_;  // another server's state: the clock's time
  }
  ns_ = NonNegative(sim_time_ns);  // the newest state's time (a player seeking back goes back)
  heard_ = now;
  return ns_;
}

std::uint64_t BridgeClock::StampOf(const std::string& server_id, std::int64_t sim_time_ns) const {
  return set_ && server_id == server_id_ ? NonNegative(sim_time_ns) : ns_;
}

}  // namespace vdyn::foxglove
