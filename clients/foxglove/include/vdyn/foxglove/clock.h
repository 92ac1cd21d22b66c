// The bridge's clock: the one time source of its `time` messages and of every message's log time
// (Foxglove WebSocket protocol: "timestamps of published messages must originate from the same
// time source").
//
// The clock is one server's simulation time: the server of the first state heard, until that
// server restarts (a state of its id with another incarnation, once the old one has been quiet
// for a second: the new session's time, which starts again near 0) or falls silent (no state for
// `silence`: the next state's server takes over). Its own states and diagnostics keep their simulation time as their log time, and the
// clock follows the newest of its states (a player seeking back takes it back). Everything else
// — another server's states and diagnostics on the same domain, session events, worlds — is
// stamped with the clock's time when it arrives (the message's own times are in its payload).
#pragma once

#include <cstdint>
#include <string>

#include "vdyn/base/time.h"

namespace vdyn::foxglove {

class BridgeClock {
 public:
  explicit BridgeClock(base::Nanos silence) : silence_(silence) {}

  // A state arrived: the log time to give it. `changed` (when given) is set when the clock took
  // another source with it (a first server, a restart, another server after a silence).
  std::uint64_t OnState(const std::string& server_id, std::uint64_t incarnation,
                        std::int64_t sim_time_ns, base::MonoTime now, bool* changed = nullptr);
  // The log time of a message of `server_id` that carries its simulation time (diagnostics).
  std::uint64_t StampOf(const std::string& server_id, std::int64_t sim_time_ns) const;

  bool set() const { return set_; }
  std::uint64_t now_ns() const { return ns_; }  // the clock's time (0 before any state)
  const std::string& server_id() const { return server_id_; }
  std::uint64_t incarnation() const { return incarnation_; }

 private:
  base::Nanos silence_;
  bool set_ = false;
  std::string server_id_;
  std::uint64_t incarnation_ = 0;
  std::uint64_t ns_ = 0;
  base::MonoTime heard_{};
};

}  // namespace vdyn::foxglove
