#include "vdyn/foxglove/clock.h"

#include <algorithm>

namespace vdyn::foxglove {

namespace {
std::uint64_t NonNegative(std::int64_t ns) { return static_cast<std::uint64_t>(std::max<std::int64_t>(ns, 0)); }
}  // namespace

std::uint64_t BridgeClock::OnState(const std::string& server_id, std::uint64_t incarnation,
                                   std::int64_t sim_time_ns, base::MonoTime now, bool* changed) {
  if (changed != nullptr) *changed = false;
  const bool same_server = set_ && server_id == server_id_;
  if (!(same_server && incarnation == incarnation_)) {
    // Another source: it takes the clock only once the clock's has been quiet (a restart of the
    // same server after a second; another server after `silence`): two sources at once (a player
    // of a recording of a server beside that server) do not take it in turn.
    const base::Nanos quiet = same_server ? std::min(silence_, base::Seconds(1)) : silence_;
    if (set_ && now - heard_ <= quiet) return ns_;
    set_ = true;
    server_id_ = server_id;
    incarnation_ = incarnation;
    if (changed != nullptr) *changed = true;
  }
  ns_ = NonNegative(sim_time_ns);  // the newest state's time (a player seeking back goes back)
  heard_ = now;
  return ns_;
}

std::uint64_t BridgeClock::StampOf(const std::string& server_id, std::int64_t sim_time_ns) const {
  return set_ && server_id == server_id_ ? NonNegative(sim_time_ns) : ns_;
}

}  // namespace vdyn::foxglove
