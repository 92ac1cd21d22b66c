// Every state of a domain, or of one vehicle, each by one route (docs/topics.md):
//  - one vehicle: vdyn/state in that vehicle's partition (transport::VehiclePartition), so the
//    other vehicles' states are never sent here; where that reader cannot be made (DDS Security
//    permissions without the partition) vdyn/state in the default partition, the others dropped
//    here;
//  - every vehicle: vdyn/states (a server's step in one sample); where vdyn/states is not
//    permitted, vdyn/state in the default partition.
// SessionView (clients' newest state per vehicle) and the Python client (every state) read
// states through it.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"

namespace vdyn::client {

class StateReader {
 public:
  // kLatest: a client's history (the newest states of each vehicle); kEvery: a recorder's (a
  // second of states per vehicle, none overwritten while the taker keeps up).
  enum class History { kLatest, kEvery };

  StateReader(transport::Participant& participant, transport::DropCounters& drops,
              std::optional<std::uint32_t> only_vehicle, History history);
  StateReader(const StateReader&) = delete;
  StateReader& operator=(const StateReader&) = delete;

  void AttachTo(transport::Waitset& waitset);
  // Hands every state that arrived (of the vehicle, if one) to fn(state, info), info.key its
  // vehicle; a vdyn/state sample whose key is not its vehicle id is skipped. Returns how many.
  template <class F>
  int Take(F&& fn);
  // Samples DDS reports lost to these readers (on vdyn/states one sample is a step of every
  // vehicle).
  std::uint64_t SamplesLost();
  // With only_vehicle: empty when the states are read in the vehicle's partition, else why not.
  const std::string& partition_fallback() const { return partition_fallback_; }

 private:
  std::optional<std::uint32_t> filter_vehicle_;  // only_vehicle: other vehicles' states dropped
  std::string partition_fallback_;
  // One of the two: vdyn/states (every vehicle), or vdyn/state (a vehicle's partition, or the
  // default partition where the other cannot be made).
  std::unique_ptr<transport::Reader<pb::VehicleStates>> batches_;
  std::unique_ptr<transport::Reader<pb::VehicleState>> states_;
};

template <class F>
int StateReader::Take(F&& fn) {
  int n = 0;
  if (batches_) {
    (void)batches_->Take([&](const pb::VehicleStates& b, const transport::SampleInfo& info) {
      for (const pb::VehicleState& s : b.states()) {
        transport::SampleInfo one = info;
        one.key = s.vehicle_id();
        fn(s, one);
        ++n;
      }
    });
  }
  if (states_) {
    (void)states_->Take([&](const pb::VehicleState& s, const transport::SampleInfo& info) {
      if (info.key != s.vehicle_id()) return;
      if (filter_vehicle_ && s.vehicle_id() != *filter_vehicle_) return;
      fn(s, info);
      ++n;
    });
  }
  return n;
}

}  // namespace vdyn::client
