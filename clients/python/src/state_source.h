// The seam between the Python client and the client layer's state reading: every state of the
// domain (or of one vehicle) as it arrives, none overwritten while the taker keeps up within a
// second. Today it is a vdyn/state reader with the recorder's QoS (keep last 1000 per vehicle)
// filtered here; a one-vehicle reader of the client layer can replace the inside without changing
// the callers.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>

#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"

namespace vdyn::python {

class StateSource {
 public:
  // Every vehicle, or only `vehicle_id`.
  StateSource(transport::Participant& participant, std::optional<std::uint32_t> vehicle_id)
      : vehicle_(vehicle_id),
        reader_(participant, transport::TopicId::kState, &drops_,
                transport::ReaderRole::kRecorder) {}

  // Blocks until a state may be available or the timeout passes.
  bool Wait(std::chrono::nanoseconds timeout) { return reader_.Wait(timeout); }
  // Hands every state that arrived (of the vehicle, if one) to fn; returns how many.
  template <class F>
  int Take(F&& fn) {
    int n = 0;
    reader_.Take([&](const pb::VehicleState& s, const transport::SampleInfo&) {
      if (vehicle_ && s.vehicle_id() != *vehicle_) return;
      fn(s);
      ++n;
    });
    return n;
  }
  // States DDS reports lost to this reader (a taker that fell a second behind).
  std::uint64_t Lost() { return reader_.SamplesLost(); }
  transport::DropCounters& drops() { return drops_; }

 private:
  std::optional<std::uint32_t> vehicle_;
  transport::DropCounters drops_;
  transport::Reader<pb::VehicleState> reader_;
};

}  // namespace vdyn::python
