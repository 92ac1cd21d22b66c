#include "vdyn/client/session_view.h"

namespace vdyn::client {

using transport::TopicId;

SessionView::SessionView(transport::Participant& participant, Topics topics)
    : only_server_(std::move(topics.only_server)) {
  waitset_ = std::make_unique<transport::Waitset>(participant);
  if (topics.states) {
    states_ = std::make_unique<StateReader>(participant, drops_, topics.only_vehicle,
                                            StateReader::History::kLatest);
    states_->AttachTo(*waitset_);
  }
  if (topics.params) {
    params_ = std::make_unique<transport::Reader<pb::VehicleParams>>(participant, TopicId::kParams,
                                                                     &drops_);
    if (!topics.states) waitset_->Attach(*params_);
    // A removed vehicle's parameters are disposed by its server: forgotten here, or params() of
    // a removed vehicle answered with them.
    params_->on_disposed = [this](std::uint32_t key) {
      if (const auto it = vehicles_.find(key); it != vehicles_.end()) it->second.params.reset();
    };
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

const std::string& SessionView::one_vehicle_fallback() const {
  static const std::string kNone;
  return states_ ? states_->partition_fallback() : kNone;
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
  if (states_) {
    n += states_->Take(
        [&](const pb::VehicleState& s, const transport::SampleInfo& info) { OnState(s, info); });
  }
  return n;
}

void SessionView::OnState(const pb::VehicleState& s, const transport::SampleInfo& info) {
  if (!only_server_.empty() && s.server_id() != only_server_) return;
  Vehicle& v = vehicles_[s.vehicle_id()];
  v.state = s;
  v.received = base::MonotonicNow();
  v.source_timestamp_ns = info.source_timestamp_ns;
  ++v.states;
  if (on_state) on_state(s, info);
}

}  // namespace vdyn::client
