// The seam between the Python client and the client layer's state reading: every state of the
// domain (or of one vehicle) as it arrives, none overwritten while the taker keeps up within a
// second: a vdyn/state reader with the recorder's QoS (keep last 1000 per vehicle). For one
// vehicle it reads in that vehicle's partition (transport::VehiclePartition), so the other
// vehicles' states are not sent to it at all; where that reader cannot be made (DDS Security
// permissions without the partition) it reads every state and keeps the vehicle's. For every
// vehicle it reads vdyn/states (a step's states of a server in one sample) and, marked as such a
// reader, vdyn/state (other writers' states): docs/topics.md.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"
#include "vdyn/transport/topics.h"

namespace vdyn::python {

class StateSource {
 public:
  // Every vehicle, or only `vehicle_id`.
  StateSource(transport::Participant& participant, std::optional<std::uint32_t> vehicle_id)
      : vehicle_(vehicle_id) {
    if (vehicle_id) {
      try {
        reader_ = std::make_unique<transport::Reader<pb::VehicleState>>(
            participant, transport::TopicId::kState, &drops_, transport::ReaderRole::kRecorder,
            transport::VehiclePartition(*vehicle_id));
      } catch (const transport::TransportError& e) {
        partition_fallback_ = e.what();
      }
    }
    transport::ReaderRole role = transport::ReaderRole::kRecorder;
    if (!vehicle_id) {
      try {
        batches_ = std::make_unique<transport::Reader<pb::VehicleStates>>(
            participant, transport::TopicId::kStates, &drops_, transport::ReaderRole::kRecorder);
        role = transport::ReaderRole::kBatchRecorder;
      } catch (const transport::TransportError&) {
        // Not permitted (DDS Security): every state on vdyn/state.
      }
    }
    if (!reader_) {
      reader_ = std::make_unique<transport::Reader<pb::VehicleState>>(
          participant, transport::TopicId::kState, &drops_, role);
    }
    waitset_ = std::make_unique<transport::Waitset>(participant, &drops_);
    waitset_->Attach(*reader_);
    if (batches_) waitset_->Attach(*batches_);
  }

  // Blocks until a state may be available or the timeout passes.
  [[nodiscard]] bool Wait(std::chrono::nanoseconds timeout) { return waitset_->Wait(timeout); }
  // Hands every state that arrived (of the vehicle, if one) to fn; returns how many.
  template <class F>
  [[nodiscard]] int Take(F&& fn) {
    int n = 0;
    if (batches_) {
      (void)batches_->Take([&](const pb::VehicleStates& b, const transport::SampleInfo&) {
        for (const pb::VehicleState& s : b.states()) {
          fn(s);
          ++n;
        }
      });
    }
    (void)reader_->Take([&](const pb::VehicleState& s, const transport::SampleInfo&) {
      if (vehicle_ && s.vehicle_id() != *vehicle_) return;
      fn(s);
      ++n;
    });
    return n;
  }
  // Samples DDS reports lost to this reader (a taker that fell a second behind; on vdyn/states
  // one sample is a step of every vehicle).
  std::uint64_t Lost() { return reader_->SamplesLost() + (batches_ ? batches_->SamplesLost() : 0); }
  transport::DropCounters& drops() { return drops_; }
  // For one vehicle: empty when it reads in the vehicle's partition, else why it could not.
  const std::string& partition_fallback() const { return partition_fallback_; }

 private:
  std::optional<std::uint32_t> vehicle_;
  transport::DropCounters drops_;
  std::string partition_fallback_;
  std::unique_ptr<transport::Reader<pb::VehicleState>> reader_;
  std::unique_ptr<transport::Reader<pb::VehicleStates>> batches_;  // every vehicle: vdyn/states
  std::unique_ptr<transport::Waitset> waitset_;
};

}  // namespace vdyn::python
