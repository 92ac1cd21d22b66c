// A vdyn recording (MCAP) read through the recorder's own reader (vdyn_mcap, vdyn_recording):
// its channels, vehicles and their gaps (counted as `vdyn-recorder info` counts them), every state
// of a vehicle as rows of the CSV's columns, the events and the metadata.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "state_columns.h"
#include "vdyn/recorder/mcap.h"

namespace vdyn::python {

struct ChannelSummary {
  std::string topic;  // "vdyn/state/1"
  std::string dds_topic;
  std::uint32_t key = 0;
  std::uint64_t messages = 0, bytes = 0;
  std::uint64_t first_log_time_ns = 0, last_log_time_ns = 0;
};

struct VehicleSummary {
  std::uint32_t vehicle_id = 0;
  std::uint64_t states = 0;
  std::uint64_t first_step = 0, last_step = 0;
  std::uint64_t missing = 0;      // states lost (holes not explained by a spawn, reset or restore)
  std::uint64_t jumps = 0;        // holes explained by a spawn, reset or restore
  std::uint64_t largest_gap = 0;  // the largest hole counted as missing, steps (0: none)
  std::uint64_t largest_gap_from = 0;
};

struct RecordedEvent {
  std::uint64_t log_time_ns = 0;
  std::string bytes;  // vdyn.pb.SessionEvent, serialised as recorded
};

class RecordingReader {
 public:
  // Opens and scans the file once (strict: a truncated, corrupted or foreign file throws
  // mcap::McapError naming the file, the offset and the reason).
  explicit RecordingReader(const std::filesystem::path& path);

  const std::filesystem::path& path() const { return path_; }
  const std::vector<ChannelSummary>& channels() const { return channels_; }
  const std::vector<VehicleSummary>& vehicles() const { return vehicles_; }
  const std::vector<RecordedEvent>& events() const { return events_; }
  const std::vector<mcap::Metadata>& metadata() const { return metadata_; }
  std::uint64_t start_ns() const { return start_ns_; }
  std::uint64_t end_ns() const { return end_ns_; }
  std::uint64_t messages() const { return messages_; }
  bool complete() const { return complete_; }

  // Every state of a vehicle in the file, by step (log_time_ns filled; one that does not parse is
  // skipped and counted in `malformed`). Throws
  // std::out_of_range naming the vehicles the file has when it has none of this one.
  // A vehicle's states, each run (a start of the server that stepped it: a restart begins its
  // steps again) sorted by step, the runs one after another in the order they came; `run` >= 0
  // takes that run alone. Sorting all by step interleaved two runs' rows.
  StateTable States(std::uint32_t vehicle_id, int run = -1) const;

 private:
  std::filesystem::path path_;
  std::unique_ptr<mcap::Reader> reader_;
  std::vector<ChannelSummary> channels_;
  std::vector<VehicleSummary> vehicles_;
  std::vector<RecordedEvent> events_;
  std::vector<mcap::Metadata> metadata_;
  std::uint64_t start_ns_ = 0, end_ns_ = 0, messages_ = 0;
  bool complete_ = false;
};

}  // namespace vdyn::python
