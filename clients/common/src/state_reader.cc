#include "vdyn/client/state_reader.h"

#include "vdyn/transport/topics.h"

namespace vdyn::client {

using transport::ReaderRole;
using transport::TopicId;

StateReader::StateReader(transport::Participant& participant, transport::DropCounters& drops,
                         std::optional<std::uint32_t> only_vehicle, History history)
    : filter_vehicle_(only_vehicle) {
  const ReaderRole role = history == History::kEvery ? ReaderRole::kRecorder : ReaderRole::kDefault;
  if (only_vehicle) {
    try {
      states_ = std::make_unique<transport::Reader<pb::VehicleState>>(
          participant, TopicId::kState, &drops, role, transport::VehiclePartition(*only_vehicle));
    } catch (const transport::TransportError& e) {
      partition_fallback_ = e.what();
    }
  } else {
    try {
      batches_ = std::make_unique<transport::Reader<pb::VehicleStates>>(
          participant, TopicId::kStates, &drops, role);
    } catch (const transport::TransportError&) {
      // Not permitted (DDS Security): every state on vdyn/state.
    }
  }
  if (!states_ && !batches_) {
    states_ = std::make_unique<transport::Reader<pb::VehicleState>>(participant, TopicId::kState,
                                                                    &drops, role);
  }
}

void StateReader::AttachTo(transport::Waitset& waitset) {
  if (states_) waitset.Attach(*states_);
  if (batches_) waitset.Attach(*batches_);
}

std::uint64_t StateReader::SamplesLost() {
  return (states_ ? states_->SamplesLost() : 0) + (batches_ ? batches_->SamplesLost() : 0);
}

}  // namespace vdyn::client
