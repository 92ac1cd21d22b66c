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
#include <deque>
#include <filesystem>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "vdyn/recorder/mcap.h"
#include "vdyn/transport/dds.h"

namespace vdyn::base {
class Deadline;
}  // namespace vdyn::base

namespace vdyn::recorder {

struct RecordOptions {
  std::filesystem::path out;
  double duration_s = 0;                // 0: until stopped
  std::set<transport::TopicId> topics;  // empty: every topic
  std::set<std::uint32_t> vehicles;     // empty: every vehicle (events: always every one)
  std::uint64_t split_bytes = 0;        // 0: no size split
  double split_s = 0;                   // 0: no time split
  mcap::WriterOptions writer;
  std::size_t queue_bytes = 256u << 20;
  bool status_line = false;
  bool status_tty = false;  // rewrite the line in place
  std::string command_line;
  std::string branched_from;  // takeover: the recording this one continues
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
  // What was dropped, by topic: " (vdyn/state 1200, vdyn/world 1)", or "" when nothing was.
  std::string dropped_by_topic() const;
};

// The buffer's admission rule, states apart: states may fill at most three quarters of it, so
// that under overload they are dropped first and session events (checkpoints among them), inputs,
// requests, worlds and parameters still find room (the rest of the bound); the whole never
// exceeds `queue_bytes`, but by a world larger than the whole buffer, which is kept (without it a
// recording cannot be re-simulated).
bool Admits(transport::TopicId topic, std::size_t in_use, std::size_t size,
            std::size_t queue_bytes);

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
  // Blocks until the reader of `topic` has a matched writer or the deadline passes (true when it
  // has). Woken by Run's check of the matches (every 100 ms while it runs).
  bool WaitForWriters(transport::TopicId topic, const base::Deadline& deadline) const;
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

// One vehicle's states that never arrived, told apart from jumps. A forward hole in the steps is
// missing states unless a Spawned event of the vehicle (spawn, reset, teleport, restore) took
// effect at a step in it or at the step just after it (the first state of the new course); a
// step back (a restore to an earlier step, a restarted server) is a jump, and closes the holes
// of the course before it. States and events travel on different topics, so the event may come
// before or after the states around its hole: a hole counts as missing when it is seen and
// becomes a jump when its event arrives. The newest kKept holes and spawn steps are kept for that
// (an older hole stays as it was classified), so a vehicle's ledger never holds more than that.
// Without the events (a recording of some topics only) there is nothing to tell by: a hole longer
// than kGuessedJump steps is then taken for a jump.
class StepGaps {
 public:
  static constexpr std::size_t kKept = 4096;
  static constexpr std::uint64_t kGuessedJump = 5000;

  explicit StepGaps(bool spawns_known = true) : spawns_known_(spawns_known) {}

  void State(std::uint64_t step);
  void Spawned(std::uint64_t step);
  std::uint64_t missing() const { return missing_; }
  std::uint64_t jumps() const { return jumps_; }
  // The largest hole counted as missing (0 when none) and its first step.
  std::uint64_t largest() const;
  std::uint64_t largest_from() const;

 private:
  struct Hole {
    std::uint64_t from = 0, to = 0;
    bool jump = false;
    std::uint64_t size() const { return to - from + 1; }
    bool Holds(std::uint64_t spawn_step) const {
      return spawn_step >= from && spawn_step <= to + 1;
    }
  };
  const Hole* Largest() const;
  void Forget(
      const Hole& h);  // a hole leaves the kept ones: its count stays, it may be the largest
  void CloseCourse(std::uint64_t step);

  bool spawns_known_;
  bool any_ = false;
  std::uint64_t last_ = 0;
  std::uint64_t missing_ = 0, jumps_ = 0;
  std::vector<Hole> holes_;  // a ring of the newest kKept (allocated at the first hole)
  std::size_t oldest_hole_ = 0;
  std::multiset<std::uint64_t> spawns_;    // the newest kKept spawn steps, for lookup...
  std::deque<std::uint64_t> spawn_order_;  // ...and in their order of arrival, to forget the oldest
  Hole forgotten_largest_{0, 0, true};     // the largest missing hole no longer kept (jump: none)
};

// What a person should do about the kernel's cap on socket receive buffers (net.core.rmem_max),
// or empty when it leaves room. A server sends its world description (2 MB for `facility`) in
// one burst when a recorder joins, or when it starts while a recorder listens: a receive buffer
// smaller than that overflows, and the kernel drops what arrives meanwhile - world fragments
// (resent: reliable) and a few states (best effort: lost for good, "lost 2" at the start).
inline constexpr std::uint64_t kBurstReceiveBytes = 4u << 20;
std::string ReceiveBufferAdvice(std::uint64_t rmem_max_bytes);
// net.core.rmem_max as /proc says (0 when it cannot be read).
std::uint64_t KernelReceiveBufferMax();

// The file of part `index` when splitting: "run.mcap" -> "run-000.mcap".
std::filesystem::path SplitPath(const std::filesystem::path& out, int index);

}  // namespace vdyn::recorder
