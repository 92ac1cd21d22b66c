#include "vdyn/client/state_reader.h"

#include "vdyn/transport/topics.h"

namespace vdyn::client {

using transport::ReaderRole;
using transport::TopicId;

StateReader::StateReader(transport::Participant& participant, transport::DropCounters& drops,
                         std::optional<std::uint32_t> only_vehicle, History history)
    : filter_vehicle_(only_vehicle) {
  const bool every = history == History::kEvery;
  const ReaderRole plain = every ? ReaderRole::kRecorder : ReaderRole::kDefault;
  ReaderRole state_role = plain;
  if (only_vehicle) {
    try {
      states_ = std::make_unique<transport::Reader<pb::VehicleState>>(
          participant, TopicId::kState, &drops, plain, transport::VehiclePartition(*only_vehicle));
    } catch (const transport::TransportError& e) {
      partition_fallback_ = e.what();
    }
  } else {
    try {
      batches_ = std::make_unique<transport::Reader<pb::VehicleStates>>(
          participant, TopicId::kStates, &drops, plain);
      state_role = every ? ReaderRole::kBatchRecorder : ReaderRole::kBatchLatest;
    } catch (const transport::TransportError&) {
      // Not permitted (DDS Security): every state on vdyn/state.
    }
  }
  if (!states_) {
    states_ = std::make_unique<transport::Reader<pb::VehicleState>>(participant, TopicId::kState,
                                                                    &drops, state_role);
  }
}

void StateReader::AttachTo(transport::Waitset& waitset) {
  waitset.Attach(*states_);
  if (batches_) waitset.Attach(*batches_);
}

std::uint64_t StateReader::SamplesLost() {
  return states_->SamplesLost() + (batches_ ? batches_->SamplesLost() : 0);
}

}  // namespace vdyn::client
