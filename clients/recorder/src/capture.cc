#include "vdyn/recorder/capture.h"

#include <pthread.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <condition_variable>
#include <cstdio>
#include <exception>
#include <map>
#include <optional>
#include <thread>
#include <tuple>
#include <unordered_map>

#include <spdlog/spdlog.h>

#include "vdyn/base/deadline.h"
#include "vdyn/base/time.h"
#include "vdyn/io/vehicle_params.h"
#include "vdyn/recorder/output_file.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/vehicle_params.pb.h"
#include "vdyn/world.pb.h"

namespace vdyn::recorder {

using transport::TopicId;

std::uint64_t CaptureSummary::total_lost() const {
  std::uint64_t n = 0;
  for (const auto& [t, c] : topics) n += c.lost;
  return n;
}

std::uint64_t CaptureSummary::total_dropped() const {
  std::uint64_t n = 0;
  for (const auto& [t, c] : topics) n += c.dropped;
  return n;
}

std::string CaptureSummary::dropped_by_topic() const {
  std::string out;
  for (const auto& [t, c] : topics) {
    if (c.dropped == 0) continue;
    out += (out.empty() ? " (" : ", ") + std::string(transport::Spec(t).name) + " " +
           std::to_string(c.dropped);
  }
  return out.empty() ? out : out + ")";
}

bool Admits(TopicId topic, std::size_t in_use, std::size_t size, std::size_t queue_bytes) {
  // A world larger than the whole buffer (facility's is 2 MB; --queue-mb 1) could never find room
  // and was dropped: a recording without its world cannot be re-simulated. It is kept, past the
  // bound by itself (a world arrives once a server start).
  if (topic == TopicId::kWorld && size > queue_bytes) return true;
  const std::size_t bound = topic == TopicId::kState ? queue_bytes - queue_bytes / 4 : queue_bytes;
  return in_use + size <= bound;
}

void SequenceGaps::Add(std::uint64_t seq) {
  if (seen_ == 0) {
    low_ = high_ = seq;
  } else {
    low_ = std::min(low_, seq);
    high_ = std::max(high_, seq);
  }
  ++seen_;
}

std::uint64_t SequenceGaps::missing() const {
  if (seen_ == 0) return 0;
  const std::uint64_t span = high_ - low_ + 1;
  return span > seen_ ? span - seen_ : 0;
}

void StepGaps::State(std::uint64_t step) {
  if (!any_) {
    any_ = true;
    last_ = step;
    return;
  }
  if (step <= last_) {
    ++jumps_;  // back in time: a new course
    CloseCourse(step);
  } else if (step > last_ + 1) {
    Hole h{last_ + 1, step - 1, false};
    const auto it = spawns_.lower_bound(h.from);
    h.jump = spawns_known_ ? it != spawns_.end() && *it <= h.to + 1 : h.size() > kGuessedJump;
    if (h.jump) {
      ++jumps_;
    } else {
      missing_ += h.size();
    }
    if (holes_.size() < kKept) {
      holes_.push_back(h);
    } else {
      Forget(holes_[oldest_hole_]);
      holes_[oldest_hole_] = h;
      oldest_hole_ = (oldest_hole_ + 1) % kKept;
    }
  }
  last_ = step;
}

void StepGaps::Spawned(std::uint64_t step) {
  spawns_.insert(step);
  spawn_order_.push_back(step);
  if (spawn_order_.size() > kKept) {
    spawns_.erase(spawns_.find(spawn_order_.front()));
    spawn_order_.pop_front();
  }
  for (Hole& h : holes_) {
    if (h.jump || !h.Holds(step)) continue;
    h.jump = true;
    missing_ -= h.size();
    ++jumps_;
  }
}

void StepGaps::Forget(const Hole& h) {
  if (!h.jump && (forgotten_largest_.jump || h.size() > forgotten_largest_.size())) {
    forgotten_largest_ = h;
  }
}

// The course before a step back is over: its holes stay as classified, and the spawns past the
// new step belong to it (a later hole of the new course at those steps is not theirs).
void StepGaps::CloseCourse(std::uint64_t step) {
  for (const Hole& h : holes_) Forget(h);
  holes_.clear();
  oldest_hole_ = 0;
  if (spawns_.upper_bound(step) == spawns_.end()) return;
  spawns_.erase(spawns_.upper_bound(step), spawns_.end());
  std::erase_if(spawn_order_, [&](std::uint64_t s) { return s > step; });
}

const StepGaps::Hole* StepGaps::Largest() const {
  const Hole* best = forgotten_largest_.jump ? nullptr : &forgotten_largest_;
  for (const Hole& h : holes_) {
    if (!h.jump && (best == nullptr || h.size() > best->size())) best = &h;
  }
  return best;
}

std::uint64_t StepGaps::largest() const {
  const Hole* h = Largest();
  return h != nullptr ? h->size() : 0;
}

std::uint64_t StepGaps::largest_from() const {
  const Hole* h = Largest();
  return h != nullptr ? h->from : 0;
}

std::string ReceiveBufferAdvice(std::uint64_t rmem_max_bytes) {
  if (rmem_max_bytes == 0 || rmem_max_bytes >= kBurstReceiveBytes) return {};
  return "the kernel caps a socket's receive buffer at " + std::to_string(rmem_max_bytes) +
         " bytes (net.core.rmem_max): a server's world description (2 MB), sent in one burst when "
         "the recorder joins or the server starts, overflows it and the kernel drops the states "
         "that arrive meanwhile (a few, lost at the start); raise it first: "
         "sudo sysctl -w net.core.rmem_max=16777216";
}

std::uint64_t KernelReceiveBufferMax() {
  std::FILE* f = std::fopen("/proc/sys/net/core/rmem_max", "r");
  if (f == nullptr) return 0;
  unsigned long long v = 0;
  if (std::fscanf(f, "%llu", &v) != 1) v = 0;
  std::fclose(f);
  return v;
}

std::filesystem::path SplitPath(const std::filesystem::path& out, int index) {
  char suffix[16];
  std::snprintf(suffix, sizeof suffix, "-%03d", index);
  std::filesystem::path p = out;
  p.replace_filename(out.stem().string() + suffix + out.extension().string());
  return p;
}

namespace {

// How often the recorder takes from its readers at most while samples flow (Run).
constexpr base::Nanos kTakePeriod = base::Milliseconds(2);

// Vehicles whose step gaps are counted (a recording of a domain with several servers has a few
// hundred at most; past this, a writer inventing vehicle ids would only grow the ledgers).
constexpr std::size_t kMaxTrackedVehicles = 4096;

struct Entry {
  TopicId topic;
  std::uint32_t key;
  std::uint64_t log_time;
  std::uint64_t publish_time;
  std::size_t offset;
  std::uint32_t size;
};

// A run of samples and their bytes in one arena: the taker fills one while the writer drains the
// other, and both keep their capacity (no allocation once warm).
struct Batch {
  std::vector<Entry> entries;
  std::vector<std::uint8_t> bytes;
  void clear() {
    entries.clear();
    bytes.clear();
  }
};

std::string TopicShort(TopicId t) {
  std::string n = transport::Spec(t).name;
  return n.substr(n.find('/') + 1);
}

std::string Count(std::uint64_t n) {
  char b[32];
  if (n < 10'000) {
    std::snprintf(b, sizeof b, "%llu", static_cast<unsigned long long>(n));
  } else if (n < 10'000'000) {
    std::snprintf(b, sizeof b, "%.1fk", static_cast<double>(n) / 1e3);
  } else {
    std::snprintf(b, sizeof b, "%.1fM", static_cast<double>(n) / 1e6);
  }
  return b;
}

}  // namespace

struct Capture::Impl {
  transport::Participant& participant;
  RecordOptions o;
  transport::DropCounters drops;
  std::vector<std::pair<TopicId, std::unique_ptr<transport::RawReader>>> readers;
  base::WallTime wall0;
  base::MonoTime mono0;

  // The buffer between taker and writer.
  std::mutex mu;
  std::condition_variable cv;
  Batch pending;
  std::size_t writer_bytes = 0;
  // Bytes admitted past the buffer's bound (a world larger than all of it), not counted against
  // it: in `pending`, and in the batch the writer writes.
  std::size_t beyond_pending = 0, beyond_writing = 0;
  std::size_t peak = 0;
  bool done = false;
  std::exception_ptr writer_error;
  std::atomic<bool> writer_failed{false};

  // Counters: the taker's, copied for Counts() under counts_mu.
  mutable std::mutex counts_mu;
  std::map<TopicId, TopicCounts> counts;

  // The taker's checks of the matched writers, counted for WaitForWriters (which waits on cv).
  mutable std::mutex match_mu;
  mutable std::condition_variable match_cv;
  std::uint64_t match_checks = 0;

  // Gap detection (taker only).
  std::unordered_map<std::uint32_t, StepGaps> step_gaps;  // of each vehicle's states
  std::uint64_t untracked_vehicles = 0;
  std::map<std::tuple<TopicId, std::uint32_t, std::uint64_t>, SequenceGaps> sequences;

  // Writer side.
  struct File {
    std::unique_ptr<mcap::Writer> w;
    std::map<std::pair<TopicId, std::uint32_t>, std::uint16_t> channels;
    // The copies of worlds and parameters (RepeatChannelMetadata), and which are due.
    std::map<std::pair<TopicId, std::uint32_t>, std::uint16_t> repeat_channels;
    // Due copies: the file offset from which each may be written (none yet: its original's chunk
    // is still open).
    std::map<std::pair<TopicId, std::uint32_t>, std::optional<std::uint64_t>> repeats_due;
    std::uint64_t last_log = 0;
    std::map<TopicId, std::uint16_t> schemas;
    std::map<std::uint16_t, std::uint32_t> sequence;
    std::uint64_t first_log = 0;
    std::uint64_t own_messages = 0;  // not counting the world and parameters it starts with
  };
  File file;
  int part = 0;
  std::vector<std::filesystem::path> files;
  std::uint64_t bytes_closed = 0;            // bytes of files already closed
  std::atomic<std::uint64_t> disk_bytes{0};  // closed files and the open one, for the status
  // The newest world and parameters of each key, re-emitted at the start of each split part.
  struct Latched {
    std::uint64_t publish_time = 0;
    std::vector<std::uint8_t> data;
  };
  std::map<std::pair<TopicId, std::uint32_t>, Latched> latched;

  Impl(transport::Participant& p, RecordOptions options) : participant(p), o(std::move(options)) {
    o.writer.live = true;  // a killed recorder leaves its file for `recover`
    // Before anything is joined or created: an output that cannot be written (a name ending
    // with a slash, a block device, a socket), and parts, which need names of their own.
    if (CheckOutputKind(o.out) == OutputKind::kStream && (o.split_bytes > 0 || o.split_s > 0)) {
      throw OutputError(o.out.string() +
                        " is a FIFO, a device or a descriptor: --split-mb and --split-s need a "
                        "file name to number the parts after (nothing was written)");
    }
    // Room for the whole buffer in each arena from the start (address space; pages are touched
    // as they fill): a growing arena was copied to a new one, into fresh pages, each time it
    // outgrew its capacity - a third of the recorder's CPU once it fell behind at 128 vehicles,
    // which made it fall further behind.
    pending.bytes.reserve(o.queue_bytes);
  }

  std::uint64_t LogNow() const {
    return static_cast<std::uint64_t>((wall0 + (base::MonotonicNow() - mono0)).ns);
  }
  bool Wanted(TopicId t) const { return o.topics.empty() || o.topics.count(t) != 0; }
  std::filesystem::path PartPath() const {
    return (o.split_bytes > 0 || o.split_s > 0) ? SplitPath(o.out, part) : o.out;
  }

  // --- taker ----------------------------------------------------------------------------------

  // A step's states of every vehicle (vdyn/states): each is recorded as the vdyn/state message
  // of its vehicle, exactly as if it had come alone (the file does not change).
  void OnStates(const transport::RawSample& s, std::uint64_t now) {
    transport::RawSample one;
    one.info = s.info;
    one.type_name = transport::Spec(TopicId::kState).payload;
    const bool framed = wire::ForEachField(s.payload, [&](const wire::Field& f) {
      if (f.number != 1 || f.type != 2) return true;  // not a state (a later field): skipped
      const std::optional<std::uint64_t> id = wire::Number(f.bytes, 1);  // absent: vehicle 0
      one.info.key = id && *id <= UINT32_MAX ? static_cast<std::uint32_t>(*id) : 0;
      one.payload = f.bytes;
      OnSample(TopicId::kState, one, now);
      return true;
    });
    if (!framed) {
      ++counts[TopicId::kState].malformed;
      drops.Count("malformed payload on vdyn/states");
    }
  }

  void OnSample(TopicId topic, const transport::RawSample& s, std::uint64_t now) {
    if (topic == TopicId::kStates) return OnStates(s, now);
    TopicCounts& c = counts[topic];
    const std::uint32_t key = s.info.key;
    if (!o.vehicles.empty() && !ServerKeyed(topic) && topic != TopicId::kEvents && key != 0 &&
        o.vehicles.count(key) == 0) {
      return;  // filtered out (events are kept for every vehicle: their sequence shows loss)
    }
    std::optional<std::uint64_t> step, sequence;
    std::uint64_t event_vehicle = 0;
    bool spawned = false;
    const bool framed = wire::ForEachField(s.payload, [&](const wire::Field& f) {
      if (topic == TopicId::kState && f.number == 3 && f.type == 0) step = f.value;
      if (topic == TopicId::kEvents && f.type == 0) {
        if (f.number == 1) event_vehicle = f.value;
        if (f.number == 3) step = f.value;
        if (f.number == 4) sequence = f.value;
      }
      if (topic == TopicId::kEvents && f.number == 10 && f.type == 2) spawned = true;
      if (topic == TopicId::kInput && f.number == 3 && f.type == 0) sequence = f.value;
      return true;
    });
    if (!framed) {
      ++c.malformed;
      drops.Count("malformed payload on " + std::string(transport::Spec(topic).name));
      return;
    }
    // Gaps: samples that never reached the recorder.
    if (topic == TopicId::kState) {
      auto it = step_gaps.find(key);
      if (it == step_gaps.end() && step_gaps.size() < kMaxTrackedVehicles) {
        it = step_gaps.try_emplace(key, Wanted(TopicId::kEvents)).first;
      }
      if (it != step_gaps.end()) {
        const std::uint64_t before = it->second.missing();
        it->second.State(step.value_or(0));  // proto3 leaves 0 out
        c.lost = c.lost + it->second.missing() - before;
      } else if (untracked_vehicles++ == 0) {
        spdlog::warn(
            "vdyn-recorder: states of more than {} vehicles: the others' gaps are not counted",
            kMaxTrackedVehicles);
      }
    }
    if (topic == TopicId::kEvents || topic == TopicId::kInput) {
      const std::uint64_t seq = sequence.value_or(0);
      const auto id =
          std::make_tuple(topic, topic == TopicId::kEvents ? 0u : key, s.info.publication_handle);
      SequenceGaps& g = sequences[id];
      const std::uint64_t before = g.missing();
      g.Add(seq);
      c.lost = c.lost + g.missing() - before;  // goes down when a late one fills a hole
    }
    {
      std::lock_guard<std::mutex> lock(mu);
      // A world kept past the bound (Admits) takes no one else's room: its bytes are not counted.
      const std::size_t in_use =
          pending.bytes.size() + writer_bytes - beyond_pending - beyond_writing;
      if (!Admits(topic, in_use, s.payload.size(), o.queue_bytes)) {
        ++c.dropped;
        return;
      }
      if (s.payload.size() > o.queue_bytes) beyond_pending += s.payload.size();
      pending.entries.push_back(
          {topic, key, now,
           static_cast<std::uint64_t>(std::max<std::int64_t>(0, s.info.source_timestamp_ns)),
           pending.bytes.size(), static_cast<std::uint32_t>(s.payload.size())});
      pending.bytes.insert(pending.bytes.end(), s.payload.begin(), s.payload.end());
      peak = std::max(peak, in_use + s.payload.size());
    }
    ++c.messages;
    c.bytes += s.payload.size();
    // A spawn, reset or restore of a vehicle whose states are counted (and which is in the file,
    // so info sees it too): a hole in its steps around it is a jump, not lost states.
    if (spawned && event_vehicle <= UINT32_MAX) {
      const auto it = step_gaps.find(static_cast<std::uint32_t>(event_vehicle));
      if (it != step_gaps.end()) {
        const std::uint64_t before = it->second.missing();
        it->second.Spawned(step.value_or(0));
        if (it->second.missing() != before)
          counts[TopicId::kState].lost -= before - it->second.missing();
      }
    }
  }

  std::string StatusLine(double elapsed_s, std::uint64_t file_bytes, double fill) const {
    std::string line;
    char b[96];
    std::snprintf(b, sizeof b, "rec %8.1f s", elapsed_s);
    line += b;
    for (const auto& [topic, c] : counts) {
      if (c.messages == 0 && c.lost == 0 && c.dropped == 0) continue;
      line += " | " + TopicShort(topic) + " " + Count(c.messages);
      if (topic == TopicId::kState || c.bytes > 1'000'000)
        line += " " + FormatBytes(static_cast<double>(c.bytes));
      if (c.lost > 0) line += " " + Count(c.lost) + " lost";
      if (c.dropped > 0) line += " " + Count(c.dropped) + " DROPPED";
      if (c.malformed > 0) line += " " + Count(c.malformed) + " malformed";
    }
    line += " | " + FormatBytes(static_cast<double>(file_bytes)) + " on disk";
    if (fill > 0.5) {
      std::snprintf(b, sizeof b, " | BEHIND: buffer %.0f%% full", 100.0 * fill);
      line += b;
    }
    return line;
  }

  // --- writer -----------------------------------------------------------------------------------

  // `now`: the log time the new file starts at (the re-emitted world and parameters carry it).
  void OpenFile(std::uint64_t now) {
    file = File{};
    file.w = std::make_unique<mcap::Writer>(PartPath(), o.writer);
    files.push_back(PartPath());
    if (file.w->writing_to() != PartPath()) {
      spdlog::info(
          "vdyn-recorder: {} exists: it is replaced when this recording closes (until "
          "then the recording is {})",
          PartPath().string(), file.w->writing_to().string());
    }
    mcap::StringMap m;
    m["format"] = kFormatVersion;
    m["recorder_version"] = kRecorderVersion;
    m["domain"] = std::to_string(participant.domain_id());
    m["command_line"] = o.command_line;
    m["started_utc"] = FormatUtc(static_cast<std::uint64_t>(wall0.ns));
    char host[256] = {};
    gethostname(host, sizeof host - 1);
    m["host"] = host;
    std::string topics;
    for (const transport::TopicSpec& s : transport::AllTopics()) {
      if (s.id != TopicId::kStates && Wanted(s.id))
        topics += (topics.empty() ? "" : ",") + std::string(s.name);
    }
    m["topics"] = topics;
    std::string vehicles;
    for (std::uint32_t v : o.vehicles)
      vehicles += (vehicles.empty() ? "" : ",") + std::to_string(v);
    m["vehicles"] = vehicles.empty() ? "all" : vehicles;
    m["compression"] = std::string(mcap::CompressionName(o.writer.compression));
    m["rmem_max"] = std::to_string(KernelReceiveBufferMax());  // see ReceiveBufferAdvice
    if (!o.branched_from.empty()) m["branched_from"] = o.branched_from;
    if (part > 0) {
      m["part"] = std::to_string(part);
      m["previous_part"] = files[files.size() - 2].filename().string();
    }
    file.w->WriteMetadata("vdyn.recording", m);
    // A later part starts with the world and parameters in effect, so it stands on its own.
    for (const auto& [id, l] : latched) {
      WriteMessage(id.first, id.second, now, l.publish_time,
                   std::span<const std::uint8_t>(l.data.data(), l.data.size()));
    }
  }

  // A world or parameters message is written once more, in a chunk of its own at least
  // kRepeatGap bytes after the chunk that holds it (a world is a megabyte on disk: one copy, not
  // one a minute). Any one chunk, or any damaged region smaller than the gap, can then be lost
  // (a damaged file, `recover`) and the world the recording ran on is still in it. A file that
  // closes sooner gets the copy at its close (then nearer).
  static constexpr std::uint64_t kRepeatGap = 64 << 10;
  void WriteRepeats(bool closing) {
    if (file.repeats_due.empty()) return;
    bool flushed = false;
    std::vector<std::pair<TopicId, std::uint32_t>> ready;
    for (auto& [id, at] : file.repeats_due) {
      if (!at) {
        if (!flushed) file.w->Flush();  // the original's chunk ends here
        flushed = true;
        at = file.w->bytes_written() + kRepeatGap;
      }
      if (closing || *at <= file.w->bytes_written()) ready.push_back(id);
    }
    if (ready.empty()) return;
    file.w->Flush();
    for (const auto& id : ready) {
      file.repeats_due.erase(id);
      const auto l = latched.find(id);
      if (l == latched.end()) continue;
      auto ch = file.repeat_channels.find(id);
      if (ch == file.repeat_channels.end()) {
        ch = file.repeat_channels
                 .emplace(
                     id, file.w->AddChannel(Schema(id.first), ChannelTopic(id.first, id.second),
                                            "protobuf", RepeatChannelMetadata(id.first, id.second)))
                 .first;
      }
      file.w->WriteMessage(
          ch->second, file.sequence[ch->second]++, file.last_log, l->second.publish_time,
          std::span<const std::uint8_t>(l->second.data.data(), l->second.data.size()));
    }
    file.w->Flush();
  }

  std::uint16_t Schema(TopicId topic) {
    auto sc = file.schemas.find(topic);
    if (sc == file.schemas.end()) {
      const auto* d = PayloadDescriptor(topic);
      sc =
          file.schemas
              .emplace(topic, file.w->AddSchema(d->full_name(), "protobuf", FileDescriptorSetOf(d)))
              .first;
    }
    return sc->second;
  }

  void CloseFile(const std::string& reason) {
    if (!file.w) return;
    WriteRepeats(/*closing=*/true);
    mcap::StringMap m;
    const std::uint64_t now = LogNow();
    m["ended_utc"] = FormatUtc(now);
    m["reason"] = reason;
    m["duration_s"] =
        std::to_string(static_cast<double>(now - static_cast<std::uint64_t>(wall0.ns)) * 1e-9);
    {
      std::lock_guard<std::mutex> lock(counts_mu);
      for (const auto& [topic, c] : counts) {
        const std::string t = transport::Spec(topic).name;
        m[t + ".messages"] = std::to_string(c.messages);
        m[t + ".lost"] = std::to_string(c.lost);
        m[t + ".dropped"] = std::to_string(c.dropped);
        m[t + ".malformed"] = std::to_string(c.malformed);
      }
    }
    file.w->WriteMetadata("vdyn.recording.end", m);
    if (file.own_messages == 0 && file.w->Discard()) {
      // Never an empty recording in the place of one that was there.
      spdlog::warn("vdyn-recorder: nothing was recorded: {} is left as it was",
                   PartPath().string());
      file.w.reset();
      return;
    }
    file.w->Close();
    bytes_closed += file.w->bytes_written();
    disk_bytes = bytes_closed;
    file.w.reset();
  }

  void Metadata(TopicId topic, std::uint32_t key, std::span<const std::uint8_t> data) {
    if (topic == TopicId::kWorld) {
      pb::WorldDescription w;
      if (!w.ParseFromArray(data.data(), static_cast<int>(data.size()))) return;
      std::size_t triangles = 0;
      for (const pb::Mesh& mesh : w.meshes())
        triangles += static_cast<std::size_t>(mesh.indices_size() / 3);
      char hash[24];
      std::snprintf(hash, sizeof hash, "%016llx",
                    static_cast<unsigned long long>(w.terrain_hash()));
      spdlog::info(
          "vdyn-recorder: recording world '{}' of server '{}' (terrain hash {}, {} triangles)",
          w.name(), w.server_id(), hash, triangles);
      file.w->WriteMetadata("vdyn.world", {{"server_id", w.server_id()},
                                           {"name", w.name()},
                                           {"terrain_hash", hash},
                                           {"step_ns", std::to_string(w.step_ns())},
                                           {"meshes", std::to_string(w.meshes_size())},
                                           {"triangles", std::to_string(triangles)},
                                           {"north_yaw", std::to_string(w.north_yaw())},
                                           {"vehicles", std::to_string(w.vehicles_size())}});
    } else if (topic == TopicId::kParams) {
      pb::VehicleParams p;
      if (!p.ParseFromArray(data.data(), static_cast<int>(data.size()))) return;
      file.w->WriteMetadata("vdyn.vehicle", {{"vehicle_id", std::to_string(key)},
                                             {"params", DumpVehicleParamsText(p)}});
    }
  }

  void WriteMessage(TopicId topic, std::uint32_t key, std::uint64_t log_time,
                    std::uint64_t publish_time, std::span<const std::uint8_t> data) {
    auto ch = file.channels.find({topic, key});
    if (ch == file.channels.end()) {
      const std::uint16_t id = file.w->AddChannel(Schema(topic), ChannelTopic(topic, key),
                                                  "protobuf", ChannelMetadata(topic, key));
      ch = file.channels.emplace(std::make_pair(topic, key), id).first;
    }
    if (file.first_log == 0) file.first_log = log_time;
    file.last_log = std::max(file.last_log, log_time);
    file.w->WriteMessage(ch->second, file.sequence[ch->second]++, log_time, publish_time, data);
    if (topic == TopicId::kWorld || topic == TopicId::kParams) {
      Metadata(topic, key, data);
      Latched& l = latched[{topic, key}];
      l.publish_time = publish_time;
      l.data.assign(data.begin(), data.end());
      file.repeats_due[{topic, key}].reset();  // due once its chunk has ended
    }
  }

  void WriterLoop() {
    pthread_setname_np(pthread_self(), "vdyn-rec-write");  // for top -H and perf
    Batch work;
    work.bytes.reserve(o.queue_bytes);  // as `pending` (they swap)
    try {
      OpenFile(LogNow());
      while (true) {
        {
          std::unique_lock<std::mutex> lock(mu);
          cv.wait_for(lock, std::chrono::milliseconds(50),
                      [&] { return !pending.entries.empty() || done; });
          if (pending.entries.empty() && done) break;
          std::swap(work, pending);
          writer_bytes = work.bytes.size();
          beyond_writing = beyond_pending;  // what was past the bound goes with its batch
          beyond_pending = 0;
        }
        const auto split_ns = static_cast<std::uint64_t>(base::FromSeconds(o.split_s).ns);
        for (const Entry& e : work.entries) {
          // A new part before this message when the current one is full or old enough.
          const bool split_size = o.split_bytes > 0 && file.own_messages > 0 &&
                                  file.w->bytes_written() >= o.split_bytes;
          const bool split_time =
              o.split_s > 0 && file.own_messages > 0 && e.log_time >= file.first_log + split_ns;
          if (split_size || split_time) {
            CloseFile("split");
            ++part;
            OpenFile(e.log_time);
          }
          WriteMessage(e.topic, e.key, e.log_time, e.publish_time,
                       std::span<const std::uint8_t>(work.bytes.data() + e.offset, e.size));
          ++file.own_messages;
        }
        WriteRepeats(/*closing=*/false);
        file.w->FlushIfOlder(LogNow());
        disk_bytes = bytes_closed + file.w->bytes_written();
        {
          std::lock_guard<std::mutex> lock(mu);
          writer_bytes = 0;
          beyond_writing = 0;
        }
        work.clear();
      }
      CloseFile("stopped");
    } catch (...) {
      writer_error = std::current_exception();
      writer_failed = true;
    }
  }
};

Capture::Capture(transport::Participant& participant, RecordOptions options)
    : impl_(std::make_unique<Impl>(participant, std::move(options))) {
  // The world's reader is made last, and put back in its place among the others: a server's
  // world reaching it ("recording world ...") then shows that server has matched every reader
  // made before it (a participant announces its readers in order, on one reliable stream), so
  // nothing it writes afterwards is lost to a reader it did not know yet.
  std::optional<std::size_t> world_at;
  for (const transport::TopicSpec& s : transport::AllTopics()) {
    if (s.id == TopicId::kStates || !impl_->Wanted(s.id)) continue;
    if (s.id == TopicId::kWorld) {
      impl_->counts[s.id];
      world_at = impl_->readers.size();
      continue;
    }
    impl_->counts[s.id];
    if (s.id == TopicId::kState) {
      // Every vehicle's states: from vdyn servers and players a step's in one sample on
      // vdyn/states, the one route for a reader of every vehicle. Where vdyn/states is not
      // permitted (DDS Security), vdyn/state instead.
      try {
        impl_->readers.emplace_back(
            TopicId::kStates,
            std::make_unique<transport::RawReader>(participant, TopicId::kStates, &impl_->drops,
                                                   transport::ReaderRole::kRecorder));
        continue;
      } catch (const transport::TransportError& e) {
        spdlog::warn("vdyn-recorder: cannot read vdyn/states ({}); every state on vdyn/state",
                     e.what());
      }
    }
    impl_->readers.emplace_back(
        s.id, std::make_unique<transport::RawReader>(participant, s.id, &impl_->drops,
                                                     transport::ReaderRole::kRecorder));
  }
  if (world_at) {
    auto world = std::make_unique<transport::RawReader>(participant, TopicId::kWorld, &impl_->drops,
                                                        transport::ReaderRole::kRecorder);
    impl_->readers.emplace(impl_->readers.begin() + static_cast<std::ptrdiff_t>(*world_at),
                           TopicId::kWorld, std::move(world));
  }
  if (const std::string advice = ReceiveBufferAdvice(KernelReceiveBufferMax()); !advice.empty()) {
    spdlog::warn("vdyn-recorder: {}", advice);
  }
  ready_ = true;
}

Capture::~Capture() = default;

std::uint32_t Capture::MatchedWriters(TopicId topic) const {
  std::uint32_t n = 0;  // vdyn/state's: with vdyn/states'
  for (auto& [t, reader] : impl_->readers) {
    if (t == topic || (topic == TopicId::kState && t == TopicId::kStates))
      n += reader->MatchedWriters();
  }
  return n;
}

bool Capture::WaitForWriters(TopicId topic, const base::Deadline& deadline) const {
  Impl& m = *impl_;
  std::uint64_t seen = 0;
  return base::PollUntil(
      deadline, base::Milliseconds(100),
      [&] {
        {
          std::lock_guard<std::mutex> lock(m.match_mu);
          seen = m.match_checks;
        }
        return MatchedWriters(topic) > 0;
      },
      [&](base::Nanos slice) {
        std::unique_lock<std::mutex> lock(m.match_mu);
        (void)m.match_cv.wait_for(lock, base::Chrono(slice),
                                  [&] { return m.match_checks != seen; });
      });
}

std::map<TopicId, TopicCounts> Capture::Counts() const {
  std::lock_guard<std::mutex> lock(impl_->counts_mu);
  return impl_->counts;
}

CaptureSummary Capture::Run(const std::atomic<bool>& stop) {
  Impl& m = *impl_;
  m.wall0 = base::WallNow();
  m.mono0 = base::MonotonicNow();
  const base::Nanos cpu0 = base::ProcessCpuTime();
  std::thread writer([&m] { m.WriterLoop(); });
  transport::Waitset waitset(m.participant);
  for (auto& [topic, reader] : m.readers) waitset.Attach(*reader);
  base::MonoTime last_status = m.mono0;
  base::MonoTime last_match_check{0};
  std::vector<transport::RawReader::WriterMatches> matched(m.readers.size());
  std::uint64_t last_dropped = 0;
  base::MonoTime last_warning{0};
  const auto end_ns = base::FromSeconds(m.o.duration_s).ns;
  auto take_all = [&] {
    bool any = false;
    for (auto& [topic, reader] : m.readers) {
      const TopicId t = topic;
      std::unique_lock<std::mutex> counts_lock(m.counts_mu);
      const int n =
          reader->TakeRaw([&](const transport::RawSample& s) { m.OnSample(t, s, m.LogNow()); });
      any = any || n > 0;
    }
    if (any) m.cv.notify_one();
    return any;
  };
  while (!stop.load() && !m.writer_failed.load()) {
    (void)waitset.Wait(std::chrono::milliseconds(100));
    // While samples flow, take at most every kTakePeriod: a wake-up per arriving datagram (and
    // the writer's, which each take signals) cost this thread a context switch each, about a
    // quarter of the recorder's CPU at 64 vehicles. The readers' histories (limits.h,
    // kRecorderHistoryDepth: 1,000 samples per vehicle) hold what arrives meanwhile.
    if (take_all()) base::SleepUntil(base::MonotonicNow() + kTakePeriod);
    const base::MonoTime now = base::MonotonicNow();
    if (end_ns > 0 && (now - m.mono0).ns >= end_ns) break;
    if ((now - last_match_check).ns >= 100'000'000) {
      // Say when a topic's writers come and go: a person (or a test) sees the recorder hears
      // the server before anything happens.
      last_match_check = now;
      // A writer that went and one that came between two looks (a server restarted at once)
      // leave the count as it was: the writers ever matched still tell.
      for (std::size_t i = 0; i < m.readers.size(); ++i) {
        const transport::RawReader::WriterMatches n = m.readers[i].second->Matches();
        if (n.now != matched[i].now || n.ever != matched[i].ever) {
          // (A failed look answers zeros: nothing came then.)
          const std::uint32_t came = n.ever > matched[i].ever ? n.ever - matched[i].ever : 0;
          const std::uint32_t went =
              matched[i].now + came > n.now ? matched[i].now + came - n.now : 0;
          if (came > 0 && went > 0) {
            spdlog::info("vdyn-recorder: hearing {} writer(s) on {} ({} new, {} gone)", n.now,
                         transport::Spec(m.readers[i].first).name, came, went);
          } else {
            spdlog::info("vdyn-recorder: hearing {} writer(s) on {}", n.now,
                         transport::Spec(m.readers[i].first).name);
          }
          matched[i] = n;
        }
      }
      {
        std::lock_guard<std::mutex> lock(m.match_mu);
        ++m.match_checks;
      }
      m.match_cv.notify_all();
    }
    if ((now - last_status).ns >= 1'000'000'000) {
      last_status = now;
      std::uint64_t dropped = 0, file_bytes = 0;
      double fill = 0;
      std::string line;
      {
        std::lock_guard<std::mutex> lock(m.mu);
        fill = static_cast<double>(m.pending.bytes.size() + m.writer_bytes) /
               static_cast<double>(m.o.queue_bytes);
      }
      {
        std::lock_guard<std::mutex> lock(m.counts_mu);
        for (const auto& [t, c] : m.counts) dropped += c.dropped;
        file_bytes = m.disk_bytes.load();
        line = m.StatusLine((now - m.mono0).seconds(), file_bytes, fill);
      }
      if (dropped > last_dropped && (now - last_warning).ns >= 10'000'000'000) {
        last_warning = now;
        spdlog::warn(
            "vdyn-recorder is falling behind: {} messages dropped so far (the buffer of {} "
            "is full: the disk or the compression cannot keep up)",
            dropped, FormatBytes(static_cast<double>(m.o.queue_bytes)));
      }
      last_dropped = dropped;
      if (m.o.status_line) {
        std::fprintf(stderr, m.o.status_tty ? "\r%s\033[K" : "%s\n", line.c_str());
        std::fflush(stderr);
      }
    }
  }
  take_all();  // what arrived up to the stop
  {
    std::lock_guard<std::mutex> lock(m.mu);
    m.done = true;
  }
  m.cv.notify_one();
  writer.join();
  if (m.o.status_line && m.o.status_tty) std::fprintf(stderr, "\n");
  if (m.writer_error) std::rethrow_exception(m.writer_error);
  CaptureSummary s;
  s.files = m.files;
  s.topics = Counts();
  for (const auto& [t, c] : s.topics) s.messages += c.messages;
  s.bytes_on_disk = m.bytes_closed;
  s.seconds = (base::MonotonicNow() - m.mono0).seconds();
  s.cpu_seconds = (base::ProcessCpuTime() - cpu0).seconds();
  s.queue_peak_bytes = m.peak;
  for (auto& [topic, reader] : m.readers) s.dds_samples_lost += reader->SamplesLost();
  return s;
}

}  // namespace vdyn::recorder
