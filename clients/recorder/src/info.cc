// `vdyn-recorder info FILE`: what a recording holds - channels, counts, time range, vehicles,
// world, gaps - and whether it re-simulates (decided from its events and world, without physics).

#include <algorithm>
#include <cstdio>
#include <map>
#include <set>

#include "vdyn/base/text.h"
#include "vdyn/recorder/capture.h"
#include "vdyn/recorder/commands.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/session.pb.h"
#include "vdyn/world.pb.h"

namespace vdyn::recorder {

using transport::TopicId;

namespace {

struct ChannelStats {
  std::uint64_t messages = 0, bytes = 0, first = 0, last = 0;
  std::uint64_t malformed = 0;  // vdyn payloads that do not parse as the topic's type
  std::string note;             // a foreign channel: what it is
};

// A rate is worth printing for a stream, not for a few messages: at least 10 over a second.
bool RateMeaningful(const ChannelStats& c) {
  return c.messages >= 10 && c.last - c.first >= 1'000'000'000ull;
}

struct VehicleStats {
  std::uint64_t states = 0;
  std::uint64_t first_step = 0, max_step = 0;
  bool any = false;
  std::int64_t step_ns = 0;
  StepGaps gaps;
};

struct ServerEvents {
  std::set<std::uint64_t> sequences;  // each event once (they arrive vehicle by vehicle)
  std::uint64_t count = 0, first = 0, last = 0, gaps = 0, missing = 0;  // from `sequences`
  std::uint64_t impossible = 0;  // events whose sequence no server reaches (kImpossibleSequence)
  std::set<std::uint64_t> terrain_hashes;
  std::map<std::uint32_t, std::uint64_t> start_step;  // vehicle -> first spawn or checkpoint
  std::map<std::uint32_t, std::string> branched_from;
};

// What `info` keeps of a world description: its name and counts, not its meshes.
struct WorldSeen {
  std::string name;
  std::uint64_t terrain_hash = 0;
  std::size_t meshes = 0, triangles = 0;
  std::int64_t step_ns = 0;
};

// A recovered file's "vdyn.recovered" metadata, as a person reads it: where it came from, what
// was left out and when, what no CRC vouches for.
void PrintRecovered(const std::vector<mcap::Metadata>& meta, std::uint64_t first,
                    std::ostream& out) {
  auto secs = [first](const std::string& ns) {
    const std::uint64_t v = std::strtoull(ns.c_str(), nullptr, 10);
    char b[32];
    // Signed: a lost chunk may lie before the first message kept.
    std::snprintf(b, sizeof b, "%.3f",
                  (static_cast<double>(v) - static_cast<double>(first)) * 1e-9);
    return std::string(b);
  };
  // "a-b,c-d" (ns) as "0.250 .. 0.500 s, ..."
  auto ranges = [&](const std::string& text) {
    std::string o;
    std::size_t at = 0;
    while (at < text.size()) {
      std::size_t end = text.find(',', at);
      if (end == std::string::npos) end = text.size();
      const std::string r = text.substr(at, end - at);
      const std::size_t dash = r.find('-');
      if (dash != std::string::npos) {
        o += (o.empty() ? "" : ", ") + secs(r.substr(0, dash)) + " .. " + secs(r.substr(dash + 1)) +
             " s";
      }
      at = end + 1;
    }
    return o;
  };
  for (const mcap::Metadata& m : meta) {
    if (m.name != "vdyn.recovered") continue;
    auto get = [&](const char* k) {
      const auto it = m.values.find(k);
      return it == m.values.end() ? std::string() : it->second;
    };
    out << "recovered   from " << Printable(get("from")) << " (" << get("file_size")
        << " bytes): " << (get("closed") == "no" ? "it was not closed" : "it was closed")
        << "; its data-section CRC " << (get("data_crc").empty() ? "?" : get("data_crc"))
        << "; its summary " << (get("summary").empty() ? "?" : get("summary")) << "\n";
    for (const auto& [k, v] : m.values) {
      if (k.rfind("damage.", 0) == 0) out << "  damaged   " << Printable(v, 400) << "\n";
      if (k.rfind("note.", 0) == 0) out << "  note      " << Printable(v, 400) << "\n";
    }
    const std::string lost = get("messages_lost"), lost_at = get("lost_log_ns");
    if (!lost.empty() && lost != "0") {
      out << "  lost      " << lost << " messages known lost"
          << (lost_at.empty() ? "" : ", log time " + ranges(lost_at)) << "\n";
    }
    const std::string unchecked = get("unchecked_messages");
    if (!unchecked.empty() && unchecked != "0") {
      out << "  UNCHECKED " << unchecked
          << " messages had no CRC that held in the source (log time "
          << ranges(get("unchecked_log_ns"))
          << "): kept in chunks without a CRC; nothing tells whether they are intact\n";
    }
    if (get("damage.000").empty() && (lost.empty() || lost == "0") &&
        (unchecked.empty() || unchecked == "0")) {
      out << "  nothing was left out\n";
    }
  }
}

// `info`, as its stages: what the recording says of itself (metadata), one scan of every
// message, the per-server sums, then one paragraph each.
class Info {
 public:
  Info(const std::filesystem::path& path, std::ostream& out)
      : path_(path), reader_(path), out_(out) {}

  int Run() {
    ReadWhatWasRecorded();
    ScanMessages();
    SumServers();
    PrintFile();
    PrintRecorded();
    PrintWorldsAndVehicles();
    PrintChannels();
    PrintGaps();
    PrintRecovered(meta_, first_, out_);
    for (const std::string& note : IntegrityNotes({}, scan_, unchecked_states_, "states")) {
      out_ << "            " << note << "\n";
    }
    PrintEvents();
    PrintResimulates();
    return 0;
  }

 private:
  // A recording made without the events (`record --topics`, as its metadata says; for a file of
  // another writer, as its summary's channels say) has only the length of a hole to go by.
  void ReadWhatWasRecorded() {
    bool told = false;
    for (const mcap::Metadata& m : ReadMetadata(reader_)) {
      const auto topics = m.values.find("topics");
      if (m.name != "vdyn.recording" || topics == m.values.end()) continue;
      events_recorded_ =
          topics->second.find(transport::Spec(TopicId::kEvents).name) != std::string::npos;
      told = true;
    }
    if (const auto summary = told ? std::nullopt : reader_.ReadSummary()) {
      events_recorded_ = false;
      for (const mcap::Channel& c : summary->channels) {
        events_recorded_ |= c.topic.rfind(transport::Spec(TopicId::kEvents).name, 0) == 0;
      }
    }
  }

  void ScanMessages() {
    Progress progress("info");
    RecordingVisitor v;
    v.on_progress = [&](double f) { progress.Update(f); };
    v.on_metadata = [&](const mcap::Metadata& m) { meta_.push_back(m); };
    v.on_foreign = [&](const mcap::Channel& c, const mcap::Schema* schema, const mcap::Message& m) {
      OnForeign(c, schema, m);
    };
    v.on_message = [&](const RecordedMessage& m) { OnMessage(m); };
    scan_ = ScanRecording(reader_, v);
    for (const mcap::ChunkIndex& c : reader_.Chunks()) {
      ++compression_chunks_[c.compression.empty() ? "none" : c.compression];
      packed_ += c.compressed_size;
      unpacked_ += c.uncompressed_size;
    }
    progress.Finish();
  }

  void Seen(std::uint64_t log_time) {
    ++messages_;
    if (first_ == 0 || log_time < first_) first_ = log_time;
    last_ = std::max(last_, log_time);
  }

  void OnForeign(const mcap::Channel& c, const mcap::Schema* schema, const mcap::Message& m) {
    Seen(m.log_time);
    ++foreign_messages_;
    ChannelStats& cs = channels_[Printable(c.topic) + " #" + std::to_string(c.id)];
    if (cs.messages == 0) {
      cs.first = m.log_time;
      cs.note = "not a vdyn channel: " +
                (schema == nullptr ? std::string("no schema")
                                   : "schema '" + Printable(schema->name) + "' (" +
                                         (schema->encoding.empty() ? "no encoding"
                                                                   : Printable(schema->encoding)) +
                                         ")") +
                ", messages " +
                (c.message_encoding.empty() ? "unencoded" : Printable(c.message_encoding));
    }
    ++cs.messages;
    cs.bytes += m.data.size();
    cs.last = std::max(cs.last, m.log_time);
  }

  void OnMessage(const RecordedMessage& m) {
    Seen(m.log_time);
    ChannelStats& c = channels_[ChannelTopic(m.topic, m.key) + (m.repeat ? " (copies)" : "")];
    if (c.messages == 0) c.first = m.log_time;
    ++c.messages;
    c.bytes += m.data.size();
    c.last = std::max(c.last, m.log_time);
    const bool read = m.topic == TopicId::kState    ? OnState(m)
                      : m.topic == TopicId::kEvents ? OnEvent(m)
                      : m.topic == TopicId::kWorld  ? OnWorld(m)
                                                    : true;
    if (!read) ++c.malformed;
  }

  VehicleStats& Vehicle(std::uint32_t id) {
    auto it = vehicles_.find(id);
    if (it == vehicles_.end()) {
      it = vehicles_.emplace(id, VehicleStats{.gaps = StepGaps(events_recorded_)}).first;
    }
    return it->second;
  }

  // The fields the gaps need, and a check that the payload is a state of this vehicle: a
  // foreign writer's garbage under our names must not become steps.
  bool OnState(const RecordedMessage& m) {
    const std::optional<StateFields> fields = ReadStateFields(m.data, m.key);
    if (!fields) return false;
    unchecked_states_ += m.unchecked ? 1 : 0;
    VehicleStats& vs = Vehicle(m.key);
    if (!vs.any) {
      vs.any = true;
      vs.first_step = fields->step;
      vs.step_ns = static_cast<std::int64_t>(fields->step_ns);
    }
    vs.gaps.State(fields->step);
    vs.max_step = std::max(vs.max_step, fields->step);
    ++vs.states;
    return true;
  }

  // A server's event names it and is keyed by its vehicle.
  bool OnEvent(const RecordedMessage& m) {
    pb::SessionEvent e;
    if (!e.ParseFromArray(m.data.data(), static_cast<int>(m.data.size())) ||
        e.server_id().empty() || e.vehicle_id() != m.key) {
      return false;
    }
    ServerEvents& s = servers_[{Printable(e.server_id()), e.incarnation()}];
    if (e.sequence() >= kImpossibleSequence) {
      ++s.impossible;
      return true;
    }
    s.sequences.insert(e.sequence());
    if (e.has_spawned()) {
      // Only a vehicle with states has steps to tell about (its first state starts them).
      if (const auto it = vehicles_.find(e.vehicle_id()); it != vehicles_.end()) {
        it->second.gaps.Spawned(e.step());
      }
    }
    if (e.has_spawned() || e.has_checkpoint()) {
      s.terrain_hashes.insert(e.has_spawned() ? e.spawned().terrain_hash()
                                              : e.checkpoint().terrain_hash());
      s.start_step.try_emplace(e.vehicle_id(), e.step());
      if (e.has_spawned() && !e.spawned().branched_from().empty()) {
        s.branched_from[e.vehicle_id()] = Printable(e.spawned().branched_from());
      }
    }
    return true;
  }

  bool OnWorld(const RecordedMessage& m) {
    pb::WorldDescription w;
    if (!w.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) return false;
    WorldSeen& seen = worlds_[{Printable(w.server_id()), w.incarnation()}];
    seen = {Printable(w.name()), w.terrain_hash(), static_cast<std::size_t>(w.meshes_size()), 0,
            w.step_ns()};
    for (const pb::Mesh& mesh : w.meshes()) {
      seen.triangles += static_cast<std::size_t>(mesh.indices_size() / 3);
    }
    return true;
  }

  void SumServers() {
    for (auto& [id, s] : servers_) {
      if (s.sequences.empty()) continue;
      s.count = s.sequences.size();
      s.first = *s.sequences.begin();
      s.last = *s.sequences.rbegin();
      std::uint64_t prev = s.first;
      for (const std::uint64_t q : s.sequences) {
        if (q > prev + 1) {
          ++s.gaps;
          s.missing += q - prev - 1;
        }
        prev = q;
      }
    }
  }

  double T(std::uint64_t ns) const {
    return first_ == 0 ? 0.0 : static_cast<double>(ns - first_) * 1e-9;
  }

  void PrintFile() {
    std::string comp;
    for (const auto& [name, n] : compression_chunks_) {
      comp += (comp.empty() ? "" : ", ") + std::to_string(n) + " " + name;
    }
    const std::string foreign =
        foreign_messages_ == 0 ? std::string()
                               : ", " + std::to_string(foreign_messages_) + " of them not vdyn " +
                                     (foreign_messages_ == 1 ? "messages" : "messages");
    char line[512];
    std::snprintf(
        line, sizeof line, "file        %s (%s; %s%s; chunks: %s; %.0f%% of the raw size)\n",
        Printable(path_.string(), 400).c_str(),
        FormatBytes(static_cast<double>(reader_.size())).c_str(),
        Count(messages_, "message", "messages").c_str(), foreign.c_str(),
        comp.empty() ? "none" : comp.c_str(),
        unpacked_ > 0 ? 100.0 * static_cast<double>(packed_) / static_cast<double>(unpacked_)
                      : 100.0);
    out_ << line;
    const std::string library = reader_.header_library();
    out_ << "written by  " << (library.empty() ? "(not named in its header)" : Printable(library))
         << (scan_.summary ? ", closed with index and summary\n"
                           : ", closed without a summary (no index: every reader must scan it)\n");
    // What the CRCs cover: a chunk whose CRC is 0 is checked only by the data section's CRC.
    const bool data_crc = scan_.data_crc == mcap::ScanResult::DataCrc::kMatched;
    if (scan_.chunks_unchecked == 0) {
      out_ << "integrity   every chunk's CRC checked"
           << (data_crc ? ", and the data section's\n" : "; the data section has no CRC\n");
    } else if (data_crc) {
      out_ << "integrity   " << scan_.chunks_unchecked << " of "
           << Count(scan_.chunks, "chunk", "chunks")
           << " carry no CRC of their own; the data section's CRC covers them (checked)\n";
    } else {
      out_ << "integrity   UNCHECKED: " << scan_.chunks_unchecked << " of "
           << Count(scan_.chunks, "chunk", "chunks") << " ("
           << Count(scan_.messages_unchecked, "message", "messages")
           << ") carry no CRC and the data section has none: nothing checked their bytes\n";
    }
  }

  void PrintRecorded() {
    for (const mcap::Metadata& m : meta_) {
      if (m.name != "vdyn.recording") continue;
      auto get = [&](const char* k) {
        const auto it = m.values.find(k);
        return it == m.values.end() ? std::string() : Printable(it->second);
      };
      out_ << "recorded    " << get("started_utc") << " on domain " << get("domain") << " (host "
           << get("host") << ")"
           << (get("part").empty() ? ""
                                   : ", part " + get("part") + " after " + get("previous_part"))
           << "\n";
      out_ << "command     "
           << Printable(m.values.count("command_line") ? m.values.at("command_line") : "", 400)
           << "\n";
      if (get("vehicles") != "all" || get("topics").find("vdyn/diagnostics") == std::string::npos) {
        out_ << "filters     topics " << get("topics") << "; vehicles " << get("vehicles") << "\n";
      }
      if (!get("branched_from").empty())
        out_ << "branched    from " << get("branched_from") << "\n";
    }
    char line[512];
    std::snprintf(line, sizeof line, "time        %s (log time %s .. %s)\n",
                  FormatDuration(T(last_)).c_str(), first_ ? FormatUtc(first_).c_str() : "-",
                  last_ ? FormatUtc(last_).c_str() : "-");
    out_ << line;
  }

  void PrintWorldsAndVehicles() {
    for (const auto& [server, w] : worlds_) {
      out_ << "world       '" << w.name << "' of " << Name(server) << ": terrain hash "
           << base::FormatHex(w.terrain_hash, 16) << ", " << Count(w.meshes, "mesh", "meshes")
           << ", " << Count(w.triangles, "triangle", "triangles") << ", step "
           << static_cast<double>(w.step_ns) * 1e-6 << " ms\n";
    }
    if (worlds_.empty()) out_ << "world       none recorded\n";
    out_ << "vehicles    " << (vehicles_.empty() ? "no states recorded" : "") << "\n";
    for (const auto& [id, vs] : vehicles_) {
      const double h = static_cast<double>(vs.step_ns) * 1e-9;
      char line[512];
      std::snprintf(
          line, sizeof line,
          "  %-9u steps %llu..%llu (%.3f .. %.3f s of simulation), %s, %llu missing", id,
          static_cast<unsigned long long>(vs.first_step),
          static_cast<unsigned long long>(vs.max_step), static_cast<double>(vs.first_step) * h,
          static_cast<double>(vs.max_step + 1) * h, Count(vs.states, "state", "states").c_str(),
          static_cast<unsigned long long>(vs.gaps.missing()));
      out_ << line;
      if (vs.gaps.jumps() > 0) {
        out_ << " ("
             << Count(vs.gaps.jumps(), "jump: a restart or restore", "jumps: restarts or restores")
             << ")";
      }
      out_ << "\n";
    }
  }

  void PrintChannels() {
    out_ << "channels\n";
    for (const auto& [name, c] : channels_) {
      char rate[32] = "        -   ";
      if (RateMeaningful(c)) {
        std::snprintf(
            rate, sizeof rate, "%9.1f Hz",
            static_cast<double>(c.messages - 1) / (static_cast<double>(c.last - c.first) * 1e-9));
      }
      char line[512];
      std::snprintf(line, sizeof line, "  %-30s %9llu msgs %s %10s   %8.3f .. %8.3f s",
                    name.c_str(), static_cast<unsigned long long>(c.messages), rate,
                    FormatBytes(static_cast<double>(c.bytes)).c_str(), T(c.first), T(c.last));
      out_ << line;
      if (c.malformed > 0) {
        out_ << "  (" << c.malformed << (c.malformed == 1 ? " does" : " do")
             << " not parse as the topic's type)";
      }
      if (!c.note.empty()) out_ << "  (" << c.note << ")";
      out_ << "\n";
    }
  }

  // States and events that never reached the recorder, and what it counted itself.
  void PrintGaps() {
    std::string gaps;
    for (const auto& [id, vs] : vehicles_) {
      if (vs.gaps.missing() == 0) continue;
      gaps += "\n  vehicle " + std::to_string(id) + ": " +
              Count(vs.gaps.missing(), "state", "states") + " missing (largest gap " +
              Count(vs.gaps.largest(), "step", "steps") + ", from step " +
              std::to_string(vs.gaps.largest_from()) + ")";
    }
    for (const auto& [server, s] : servers_) {
      if (s.missing > 0) {
        gaps += "\n  " + Name(server) + ": " + Count(s.missing, "event", "events") +
                " missing in " + Count(s.gaps, "gap", "gaps");
      }
      if (s.impossible > 0) {
        gaps += "\n  " + Name(server) + ": " + Count(s.impossible, "event has", "events have") +
                " a sequence number no server reaches (2^48 or more: damaged or foreign): not "
                "counted";
      }
    }
    for (const mcap::Metadata& m : meta_) {
      if (m.name != "vdyn.recording.end") continue;
      for (const auto& [k, val] : m.values) {
        const bool loss =
            k.ends_with(".lost") || k.ends_with(".dropped") || k.ends_with(".malformed");
        if (loss && val != "0") {
          gaps += "\n  the recorder counted " + Printable(val) + " " + k.substr(k.rfind('.') + 1) +
                  " on " + Printable(k.substr(0, k.rfind('.')));
        }
      }
    }
    for (const auto& [name, c] : channels_) {
      if (c.malformed == 0) continue;
      gaps += "\n  " + name + ": " + std::to_string(c.malformed) + " of " +
              Count(c.messages, "message", "messages") + (c.malformed == 1 ? " does" : " do") +
              " not parse as the topic's type: left out of the counts above";
    }
    out_ << "gaps" << (gaps.empty() ? "        none" : gaps) << "\n";
  }

  void PrintEvents() {
    for (const auto& [server, s] : servers_) {
      if (s.count == 0) continue;
      out_ << "events      " << Name(server) << ": " << Count(s.count, "event", "events")
           << ", sequence " << s.first << ".." << s.last << (s.gaps ? "" : ", no gap") << "\n";
      for (const auto& [veh, from] : s.branched_from) {
        out_ << "            vehicle " << veh << " continues " << from << "\n";
      }
    }
  }

  // Why not: the world it ran on, a start for each vehicle, session events at all.
  std::string WhyNotResimulated() const {
    std::uint64_t event_messages = 0, bad_events = 0;
    std::string named;  // channels named like our events that hold something else
    for (const auto& [name, c] : channels_) {
      if (name.rfind(transport::Spec(TopicId::kEvents).name, 0) != 0) continue;
      if (c.note.empty()) {
        event_messages += c.messages;
        bad_events += c.malformed;
      } else {
        named += (named.empty() ? "" : ", ") + name.substr(0, name.find(" #"));
      }
    }
    if (servers_.empty()) {
      return event_messages > 0 ? "the " + std::to_string(bad_events) +
                                      " messages on vdyn/events " + "do not parse as session events"
             : !named.empty()
                 ? "no session events: " + named + " holds another type (not a vdyn channel)"
                 : "no session events recorded (vdyn/events)";
    }
    for (const auto& [server, s] : servers_) {
      const auto w = worlds_.find(server);
      if (w == worlds_.end()) return "no world description of " + Name(server) + " (vdyn/world)";
      if (s.terrain_hashes.size() > 1 ||
          (s.terrain_hashes.size() == 1 && *s.terrain_hashes.begin() != w->second.terrain_hash)) {
        return "the events name another terrain than the recorded world";
      }
    }
    for (const auto& [id, vs] : vehicles_) {
      bool start = false;
      for (const auto& [server, s] : servers_) start |= s.start_step.count(id) > 0;
      if (!start) return "vehicle " + std::to_string(id) + " has no spawn or checkpoint event";
    }
    return {};
  }

  void PrintResimulates() {
    const std::string no = WhyNotResimulated();
    if (!no.empty()) {
      out_ << "re-simulates no: " << no << "\n";
      return;
    }
    std::string partly;  // what verify cannot cover: it re-simulates around it
    for (const auto& [server, s] : servers_) {
      if (s.gaps > 0) {
        partly += "; " + Count(s.missing, "event", "events") + " of " + Name(server) + " " +
                  (s.missing == 1 ? "is" : "are") + " missing (" + Count(s.gaps, "gap", "gaps") +
                  ")";
      }
    }
    std::string starts;
    for (const auto& [id, vs] : vehicles_) {
      for (const auto& [server, s] : servers_) {
        if (auto it = s.start_step.find(id); it != s.start_step.end()) {
          starts += (starts.empty() ? "" : ", ") + std::string("vehicle ") + std::to_string(id) +
                    " from step " + std::to_string(it->second);
          break;
        }
      }
    }
    if (starts.empty()) starts = "no states to check";
    if (!partly.empty()) {
      out_ << "re-simulates in parts: " << starts << partly
           << ": `vdyn-recorder verify` re-simulates up to each gap and again from the next "
              "checkpoint after it, and says which steps it could not verify\n";
    } else {
      out_ << "re-simulates yes: " << starts
           << " (`vdyn-recorder verify` checks every state hash)\n";
    }
  }

  const std::filesystem::path path_;
  const mcap::Reader reader_;
  std::ostream& out_;
  bool events_recorded_ = true;
  std::map<std::string, ChannelStats> channels_;
  std::map<std::uint32_t, VehicleStats> vehicles_;
  // By server id (as printable) and start (SessionEvent.incarnation): a server restarted with
  // the same id numbers its events afresh.
  using ServerKey = std::pair<std::string, std::uint64_t>;
  std::map<ServerKey, ServerEvents> servers_;
  std::map<ServerKey, WorldSeen> worlds_;
  // "server 'vdyn'", or "server 'vdyn' (its start 2 of 3)" when the recording holds several
  // starts of that id (its events or worlds), numbered in time order (an incarnation is a
  // start time).
  std::string Name(const ServerKey& key) const {
    std::set<std::uint64_t> starts;
    for (const auto& [k, s] : servers_) {
      if (k.first == key.first) starts.insert(k.second);
    }
    for (const auto& [k, w] : worlds_) {
      if (k.first == key.first) starts.insert(k.second);
    }
    const std::string name = "server '" + key.first + "'";
    if (starts.size() <= 1) return name;
    const auto at = std::distance(starts.begin(), starts.find(key.second)) + 1;
    return name + " (its start " + std::to_string(at) + " of " + std::to_string(starts.size()) +
           ")";
  }
  std::vector<mcap::Metadata> meta_;
  std::uint64_t first_ = 0, last_ = 0, messages_ = 0, foreign_messages_ = 0;
  std::uint64_t unchecked_states_ = 0;
  std::map<std::string, std::uint64_t> compression_chunks_;
  std::uint64_t packed_ = 0, unpacked_ = 0;
  mcap::ScanResult scan_;
};

}  // namespace

int RunInfo(const std::filesystem::path& path, std::ostream& out) {
  return Info(path, out).Run();
}

}  // namespace vdyn::recorder
