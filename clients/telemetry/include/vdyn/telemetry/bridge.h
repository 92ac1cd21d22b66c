// The telemetry bridge: the newest state of one vehicle, taken from DDS, sent as OutSim and
// OutGauge datagrams at fixed rates (not per state: the server publishes 1000 states a second and
// a dashboard wants 60). Each stream has its own thread and FixedRateLoop; a tick sends the newest
// state, or nothing when that state is older than the stale limit (the server stopped, the link
// is cut): a motion platform then holds still instead of replaying the last pose.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "vdyn/base/time.h"
#include "vdyn/client/session_view.h"
#include "vdyn/state.pb.h"
#include "vdyn/telemetry/convert.h"
#include "vdyn/telemetry/udp.h"
#include "vdyn/transport/dds.h"
#include "vdyn/vehicle_params.pb.h"

namespace vdyn::telemetry {

struct BridgeConfig {
  std::uint32_t vehicle_id = 1;
  std::vector<Endpoint> outsim, outgauge;  // either may be empty, not both
  double outsim_hz = 100.0;
  double outgauge_hz = 60.0;
  std::int32_t outsim_id = 0;    // 0: no ID (64-byte packets), else 68 bytes ending in it
  std::int32_t outgauge_id = 0;  // 0: 92 bytes, else 96
  base::Nanos stale_after = base::Milliseconds(500);
  std::string car = "VDYN";
};

class Bridge {
 public:
  Bridge(transport::Participant& participant, BridgeConfig config);
  ~Bridge();
  Bridge(const Bridge&) = delete;
  Bridge& operator=(const Bridge&) = delete;

  // Runs until `stop`: takes states, and from the stream threads sends packets. `say` gets lines
  // for a person: the start, the first state, a pause (stale) and a resume at once, and a status
  // line every `status_period` (none when it is zero).
  void Run(const std::atomic<bool>& stop, const std::function<void(const std::string&)>& say,
           base::Nanos status_period);

  std::string StatusLine();
  std::string Summary() const;

  struct StreamCounters {
    std::uint64_t ticks = 0;    // ticks of the stream's loop
    std::uint64_t held = 0;     // ticks that sent nothing: no state yet, or a stale one
    std::uint64_t skipped = 0;  // ticks the loop skipped (this machine was busy)
    std::uint64_t sent = 0;     // datagrams sent (one per destination per tick)
    std::uint64_t errors = 0;   // datagrams the network refused
  };
  StreamCounters outsim() const;
  StreamCounters outgauge() const;
  std::uint64_t states() const { return states_.load(); }
  std::uint64_t pauses() const { return pauses_.load(); }

 private:
  struct Latest {
    bool have = false;
    pb::VehicleState state;
    base::MonoTime received;
    std::optional<pb::VehicleParams> params;
  };
  struct Stream {
    std::string name;
    double hz = 0;
    std::unique_ptr<UdpSender> sender;
    std::atomic<std::uint64_t> ticks{0}, held{0}, skipped{0};
    std::thread thread;
    std::uint64_t sent_at_status = 0;
  };
  void StreamLoop(Stream& stream, bool outsim);
  StreamCounters Counters(const Stream& s) const;

  BridgeConfig config_;
  client::SessionView view_;
  mutable std::mutex mu_;  // guards latest_
  Latest latest_;
  std::atomic<bool> stop_streams_{false};
  std::atomic<std::uint64_t> states_{0}, pauses_{0};
  Stream outsim_, outgauge_;
  base::MonoTime last_status_;
};

}  // namespace vdyn::telemetry
