// The seam between the Python client and the client layer's state reading: every state of the
// domain (or of one vehicle) as it arrives, none overwritten while the taker keeps up within a
// second (client::StateReader with the recorder's history: keep last 1000 per vehicle; one
// vehicle read in its partition, every vehicle from vdyn/states: docs/topics.md).
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "vdyn/client/state_reader.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"
#include "vdyn/transport/topics.h"

namespace vdyn::python {

class StateSource {
 public:
  // Every vehicle, or only `vehicle_id`.
  StateSource(transport::Participant& participant, std::optional<std::uint32_t> vehicle_id)
      : states_(participant, drops_, vehicle_id, client::StateReader::History::kEvery),
        waitset_(std::make_unique<transport::Waitset>(participant, &drops_)) {
    states_.AttachTo(*waitset_);
  }

  // Blocks until a state may be available or the timeout passes.
  [[nodiscard]] bool Wait(std::chrono::nanoseconds timeout) { return waitset_->Wait(timeout); }
  // Hands every state that arrived (of the vehicle, if one) to fn; returns how many.
  template <class F>
  [[nodiscard]] int Take(F&& fn) {
    return states_.Take([&](const pb::VehicleState& s, const transport::SampleInfo&) { fn(s); });
  }
  // Samples DDS reports lost to this reader (a taker that fell a second behind; on vdyn/states
  // one sample is a step of every vehicle).
  std::uint64_t Lost() { return states_.SamplesLost(); }
  transport::DropCounters& drops() { return drops_; }
  // For one vehicle: empty when it reads in the vehicle's partition, else why it could not.
  const std::string& partition_fallback() const { return states_.partition_fallback(); }

 private:
  transport::DropCounters drops_;  // before states_: its readers count here
  client::StateReader states_;
  std::unique_ptr<transport::Waitset> waitset_;
};

}  // namespace vdyn::python
