#include "vdyn/client/session_view.h"

namespace vdyn::client {

using transport::TopicId;

SessionView::SessionView(transport::Participant& participant, Topics topics) {
  waitset_ = std::make_unique<transport::Waitset>(participant);
  if (topics.states) {
    if (topics.only_vehicle) {
      try {
        states_ = std::make_unique<transport::Reader<pb::VehicleState>>(
            participant, TopicId::kState, &drops_, transport::ReaderRole::kDefault,
            transport::VehiclePartition(*topics.only_vehicle));
      } catch (const transport::TransportError& e) {
        one_vehicle_fallback_ = e.what();
        filter_vehicle_ = topics.only_vehicle;
      }
    }
    transport::ReaderRole role = transport::ReaderRole::kDefault;
    if (!topics.only_vehicle) {
      // Every vehicle: a server's step in one sample on vdyn/states, and vdyn/state marked as
      // such a reader (states of writers that do not batch, e.g. other DDS tools).
      try {
        batches_ = std::make_unique<transport::Reader<pb::VehicleStates>>(
            participant, TopicId::kStates, &drops_);
        role = transport::ReaderRole::kBatchLatest;
      } catch (const transport::TransportError&) {
        // Not permitted (DDS Security): every state on vdyn/state.
      }
    }
    if (!states_) {
      states_ = std::make_unique<transport::Reader<pb::VehicleState>>(participant, TopicId::kState,
                                                                      &drops_, role);
    }
    waitset_->Attach(*states_);
    if (batches_) waitset_->Attach(*batches_);
  }
  if (topics.params) {
    params_ = std::make_unique<transport::Reader<pb::VehicleParams>>(participant, TopicId::kParams,
                                                                     &drops_);
    if (!topics.states) waitset_->Attach(*params_);
  }
  if (topics.world) {
    world_ = std::make_unique<transport::Reader<pb::WorldDescription>>(participant,
                                                                       TopicId::kWorld, &drops_);
    if (!topics.states) waitset_->Attach(*world_);
  }
  if (topics.diagnostics) {
    diagnostics_reader_ = std::make_unique<transport::Reader<pb::Diagnostics>>(
        participant, TopicId::kDiagnostics, &drops_);
    if (!topics.states) waitset_->Attach(*diagnostics_reader_);
  }
  if (topics.inputs) {
    inputs_ = std::make_unique<transport::Reader<pb::DriverInput>>(participant, TopicId::kInput,
                                                                   &drops_);
    if (!topics.states) waitset_->Attach(*inputs_);
  }
}

const SessionView::Vehicle* SessionView::vehicle(std::uint32_t id) const {
  const auto it = vehicles_.find(id);
  return it == vehicles_.end() ? nullptr : &it->second;
}

bool SessionView::Wait(std::chrono::nanoseconds timeout) { return waitset_->Wait(timeout); }

int SessionView::Poll() {
  int n = 0;
  if (world_) {
    n += world_->Take([&](const pb::WorldDescription& w, const transport::SampleInfo& info) {
      if (on_world) on_world(w, info);
      worlds_[w.server_id()] = w;
      ++world_version_;
    });
  }
  if (params_) {
    n += params_->Take([&](const pb::VehicleParams& p, const transport::SampleInfo& info) {
      vehicles_[info.key].params = p;
    });
  }
  if (diagnostics_reader_) {
    n += diagnostics_reader_->Take([&](const pb::Diagnostics& d, const transport::SampleInfo&) {
      diagnostics_[d.server_id()] = d;
    });
  }
  if (inputs_) {
    n += inputs_->Take([&](const pb::DriverInput& in, const transport::SampleInfo& info) {
      if (info.key != in.vehicle_id()) return;
      vehicles_[in.vehicle_id()].input = in;
      if (on_input) on_input(in, info);
    });
  }
  if (batches_) {
    n += batches_->Take([&](const pb::VehicleStates& b, const transport::SampleInfo& info) {
      for (const pb::VehicleState& s : b.states()) {
        transport::SampleInfo one = info;
        one.key = s.vehicle_id();
        OnState(s, one);
      }
    });
  }
  if (states_) {
    n += states_->Take([&](const pb::VehicleState& s, const transport::SampleInfo& info) {
      if (info.key != s.vehicle_id()) return;
      if (filter_vehicle_ && s.vehicle_id() != *filter_vehicle_) return;
      OnState(s, info);
    });
  }
  return n;
}

void SessionView::OnState(const pb::VehicleState& s, const transport::SampleInfo& info) {
  Vehicle& v = vehicles_[s.vehicle_id()];
  v.state = s;
  v.received = base::MonotonicNow();
  v.source_timestamp_ns = info.source_timestamp_ns;
  ++v.states;
  if (on_state) on_state(s, info);
}

}  // namespace vdyn::client
