#include "recording_reader.h"

#include <utility>

#include <map>

#include <algorithm>
#include <stdexcept>
#include <string>

#include "vdyn/base/text.h"
#include "vdyn/recorder/capture.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/session.pb.h"
#include "vdyn/transport/topics.h"

namespace vdyn::python {
namespace {

using transport::TopicId;
namespace wire = recorder::wire;

// Whether the recording holds the events (a spawn, reset or restore tells a jump from lost
// states), as `vdyn-recorder info` decides it: the recording's metadata, else the channels.
bool EventsRecorded(const mcap::Reader& reader, const std::vector<mcap::Metadata>& metadata) {
  for (const mcap::Metadata& m : metadata) {
    const auto topics = m.values.find("topics");
    if (m.name != "vdyn.recording" || topics == m.values.end()) continue;
    return topics->second.find(transport::Spec(TopicId::kEvents).name) != std::string::npos;
  }
  if (const auto summary = reader.ReadSummary()) {
    for (const mcap::Channel& c : summary->channels) {
      if (c.topic.rfind(transport::Spec(TopicId::kEvents).name, 0) == 0) return true;
    }
    return false;
  }
  return true;
}

}  // namespace

RecordingReader::RecordingReader(const std::filesystem::path& path)
    : path_(path), reader_(std::make_unique<mcap::Reader>(path)) {
  metadata_ = recorder::ReadMetadata(*reader_);
  const bool events_recorded = EventsRecorded(*reader_, metadata_);
  std::map<std::string, ChannelSummary> channels;
  struct Vehicle {
    VehicleSummary summary;
    recorder::StepGaps gaps;
  };
  std::map<std::uint32_t, Vehicle> vehicles;
  recorder::RecordingVisitor v;
  v.on_message = [&](const recorder::RecordedMessage& m) {
    ++messages_;
    if (start_ns_ == 0 || m.log_time < start_ns_) start_ns_ = m.log_time;
    end_ns_ = std::max(end_ns_, m.log_time);
    const std::string topic = recorder::ChannelTopic(m.topic, m.key);
    ChannelSummary& c = channels[topic];
    if (c.messages == 0) {
      c.topic = topic;
      c.dds_topic = transport::Spec(m.topic).name;
      c.key = m.key;
      c.first_log_time_ns = m.log_time;
    }
    ++c.messages;
    c.bytes += m.data.size();
    c.last_log_time_ns = m.log_time;
    if (m.topic == TopicId::kState) {
      const std::uint64_t step = wire::Number(m.data, 3).value_or(0);
      auto it = vehicles.find(m.key);
      if (it == vehicles.end()) {
        it = vehicles.emplace(m.key, Vehicle{{}, recorder::StepGaps(events_recorded)}).first;
        it->second.summary.vehicle_id = m.key;
        it->second.summary.first_step = step;
      }
      VehicleSummary& s = it->second.summary;
      ++s.states;
      s.first_step = std::min(s.first_step, step);
      s.last_step = std::max(s.last_step, step);
      it->second.gaps.State(step);
    } else if (m.topic == TopicId::kEvents) {
      events_.push_back({m.log_time, std::string(m.data.begin(), m.data.end())});
      pb::SessionEvent e;
      if (!e.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) return;
      if (e.has_spawned()) {
        if (const auto it = vehicles.find(e.vehicle_id()); it != vehicles.end()) {
          it->second.gaps.Spawned(e.step());
        }
      }
    }
  };
  complete_ = recorder::ScanRecording(*reader_, v).complete;
  for (auto& [topic, c] : channels) channels_.push_back(std::move(c));
  for (auto& [id, vehicle] : vehicles) {
    VehicleSummary s = vehicle.summary;
    s.missing = vehicle.gaps.missing();
    s.jumps = vehicle.gaps.jumps();
    s.largest_gap = vehicle.gaps.largest();
    s.largest_gap_from = vehicle.gaps.largest_from();
    vehicles_.push_back(s);
  }
}

StateTable RecordingReader::States(std::uint32_t vehicle_id, int run) const {
  const auto it = std::find_if(vehicles_.begin(), vehicles_.end(),
                               [&](const VehicleSummary& s) { return s.vehicle_id == vehicle_id; });
  if (it == vehicles_.end()) {
    std::string have;
    for (const auto& s : vehicles_)
      have += (have.empty() ? "" : ", ") + std::to_string(s.vehicle_id);
    throw std::out_of_range(path_.string() + " holds no states of vehicle " +
                            std::to_string(vehicle_id) +
                            (have.empty() ? std::string(" (no vehicle states at all)")
                                          : " (it has vehicle " + have + ")"));
  }
  // Each (server, start) is a run of its own, kept in the order its first state came.
  std::map<std::pair<std::string, std::uint64_t>, std::size_t> run_of;
  std::vector<StateTable> runs;
  std::vector<std::string> names;
  pb::VehicleState state;
  std::uint64_t malformed = 0;
  recorder::RecordingVisitor v;
  v.wants = [](TopicId topic) { return topic == TopicId::kState; };
  v.on_message = [&](const recorder::RecordedMessage& m) {
    if (m.topic != TopicId::kState || m.key != vehicle_id) return;
    if (!state.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) {
      ++malformed;
      return;
    }
    const auto [at, added] =
        run_of.try_emplace({state.server_id(), state.incarnation()}, runs.size());
    if (added) {
      runs.emplace_back();
      names.push_back("server '" + state.server_id() + "' start " +
                      base::FormatHex(state.incarnation(), 16));
    }
    StateTable& t = runs[at->second];
    t.Append(state);
    t.log_time_ns.push_back(m.log_time);
  };
  recorder::ScanRecording(*reader_, v);
  if (run >= 0 && static_cast<std::size_t>(run) >= runs.size()) {
    throw std::out_of_range(path_.string() + ": vehicle " + std::to_string(vehicle_id) + " has " +
                            std::to_string(runs.size()) + " run(s) (server starts): run " +
                            std::to_string(run) + " is not one (they count from 0)");
  }
  StateTable t;
  t.Reserve(it->states);
  t.log_time_ns.reserve(it->states);
  for (std::size_t k = 0; k < runs.size(); ++k) {
    runs[k].SortByStep();
    const StateTable& r = runs[k];
    t.runs.push_back(names[k] + ": steps " + std::to_string(r.step.front()) + ".." +
                     std::to_string(r.step.back()) + ", " + std::to_string(r.rows()) + " states");
    if (run < 0 || static_cast<std::size_t>(run) == k) t.Extend(r);
  }
  t.malformed = malformed;
  return t;
}

}  // namespace vdyn::python
