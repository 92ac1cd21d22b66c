// `vdyn-recorder record`: every vdyn topic of a domain, captured raw into MCAP.
//
//   taker    (the caller of Run) waits on every topic's reader, takes each sample as the bytes
//            that arrived, checks the protobuf framing, counts gaps (a state's step, an event's
//            or an input's sequence), stamps the receive time and appends it to a bounded buffer;
//            prints the status line
//   writer   swaps the buffer out and writes it: channels and schemas as topics and vehicles
//            appear, metadata as worlds and parameters arrive, small compressed chunks, a new
//            file when a split is due, and the summary at the end
//
// The buffer is bounded in bytes: a recorder whose disk or compression falls behind drops what
// does not fit, counts it per topic and says so; its memory never grows without bound. Readers use
// the recorder QoS (transport::ReaderRole::kRecorder): a take a little late loses nothing.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "vdyn/recorder/mcap.h"
#include "vdyn/transport/dds.h"

namespace vdyn::recorder {

struct RecordOptions {
  std::filesystem::path out;
  double duration_s = 0;                    // 0: until stopped
  std::set<transport::TopicId> topics;      // empty: every topic
  std::set<std::uint32_t> vehicles;         // empty: every vehicle (events: always every one)
  std::uint64_t split_bytes = 0;            // 0: no size split
  double split_s = 0;                       // 0: no time split
  mcap::WriterOptions writer;
  std::size_t queue_bytes = 256u << 20;
  bool status_line = false;
  bool status_tty = false;                  // rewrite the line in place
  std::string command_line;
  std::string branched_from;                // takeover: the recording this one continues
};

// What one topic brought, since the start.
struct TopicCounts {
  std::uint64_t messages = 0;
  std::uint64_t bytes = 0;
  std::uint64_t lost = 0;       // gaps in steps or sequence numbers: never reached the recorder
  std::uint64_t dropped = 0;    // reached it but did not fit the buffer (the recorder was behind)
  std::uint64_t malformed = 0;  // not protobuf framing: refused
};

struct CaptureSummary {
  std::vector<std::filesystem::path> files;
  std::map<transport::TopicId, TopicCounts> topics;
  std::uint64_t messages = 0;
  std::uint64_t bytes_on_disk = 0;
  double seconds = 0;
  double cpu_seconds = 0;  // this process's CPU (all threads) while recording
  std::size_t queue_peak_bytes = 0;
  std::uint64_t dds_samples_lost = 0;  // as DDS reports it
  std::uint64_t total_lost() const;
  std::uint64_t total_dropped() const;
};

class Capture {
 public:
  Capture(transport::Participant& participant, RecordOptions options);
  ~Capture();
  Capture(const Capture&) = delete;
  Capture& operator=(const Capture&) = delete;

  // Records until `stop` is set or the duration has passed, then drains and closes the file(s).
  // Throws mcap::McapError when a file cannot be written.
  CaptureSummary Run(const std::atomic<bool>& stop);
  // Set once the readers exist (samples from then on are captured): waiters may go on.
  bool ready() const { return ready_.load(); }
  // Writers matched by the reader of a topic (0 for a topic not recorded): a caller that is
  // about to cause events waits for the server's writer first.
  std::uint32_t MatchedWriters(transport::TopicId topic) const;
  // A copy of the counters so far (any thread).
  std::map<transport::TopicId, TopicCounts> Counts() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::atomic<bool> ready_{false};
};

// The sequence numbers one writer has sent (an event's, an input's) and how many of them never
// arrived. They may arrive out of order: a writer numbers its samples across every vehicle while
// a take returns them vehicle by vehicle. Missing = the span from the lowest to the highest seen,
// less those seen; a late one fills its hole again. (A writer does not repeat a number; were it
// to, the count would only go down, never below zero.)
class SequenceGaps {
 public:
  void Add(std::uint64_t seq);
  std::uint64_t missing() const;

 private:
  std::uint64_t low_ = 0, high_ = 0, seen_ = 0;
};

// The file of part `index` when splitting: "run.mcap" -> "run-000.mcap".
std::filesystem::path SplitPath(const std::filesystem::path& out, int index);

}  // namespace vdyn::recorder
