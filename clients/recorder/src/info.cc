// `vdyn-recorder info FILE`: what a recording holds - channels, counts, time range, vehicles,
// world, gaps - and whether it re-simulates (decided from its events and world, without physics).

#include <algorithm>
#include <cstdio>
#include <map>
#include <set>

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
  std::set<std::uint64_t> terrain_hashes;
  std::map<std::uint32_t, std::uint64_t> start_step;  // vehicle -> first spawn or checkpoint
  std::map<std::uint32_t, std::string> branched_from;
};

std::string Hex(std::uint64_t v) {
  char b[24];
  std::snprintf(b, sizeof b, "%016llx", static_cast<unsigned long long>(v));
  return b;
}

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
    out << "recovered   from " << get("from") << " (" << get("file_size")
        << " bytes): " << (get("closed") == "no" ? "it was not closed" : "it was closed")
        << "; its data-section CRC " << (get("data_crc").empty() ? "?" : get("data_crc"))
        << "; its summary " << (get("summary").empty() ? "?" : get("summary")) << "\n";
    for (const auto& [k, v] : m.values) {
      if (k.rfind("damage.", 0) == 0) out << "  damaged   " << v << "\n";
      if (k.rfind("note.", 0) == 0) out << "  note      " << v << "\n";
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

}  // namespace

int RunInfo(const std::filesystem::path& path, std::ostream& out) {
  mcap::Reader reader(path);
  std::map<std::string, ChannelStats> channels;
  std::map<std::uint32_t, VehicleStats> vehicles;
  // A spawn, reset or restore tells a jump from lost states. A recording made without the events
  // (`record --topics`, as its metadata says; for a file of another writer, as its summary's
  // channels say) has only the length of a hole to go by, as the recorder had.
  bool events_recorded = true;
  bool told = false;
  for (const mcap::Metadata& m : ReadMetadata(reader)) {
    const auto topics = m.values.find("topics");
    if (m.name != "vdyn.recording" || topics == m.values.end()) continue;
    events_recorded =
        topics->second.find(transport::Spec(TopicId::kEvents).name) != std::string::npos;
    told = true;
  }
  if (const auto summary = told ? std::nullopt : reader.ReadSummary()) {
    events_recorded = false;
    for (const mcap::Channel& c : summary->channels) {
      events_recorded |= c.topic.rfind(transport::Spec(TopicId::kEvents).name, 0) == 0;
    }
  }
  auto Vehicle = [&](std::uint32_t id) -> VehicleStats& {
    auto it = vehicles.find(id);
    if (it == vehicles.end()) {
      it = vehicles.emplace(id, VehicleStats{.gaps = StepGaps(events_recorded)}).first;
    }
    return it->second;
  };
  std::map<std::string, ServerEvents> servers;
  std::map<std::string, pb::WorldDescription> worlds;  // by server id (meshes dropped)
  std::vector<mcap::Metadata> meta;
  std::uint64_t first = 0, last = 0, messages = 0;
  std::map<std::string, std::uint64_t> compression_chunks;
  std::uint64_t packed = 0, unpacked = 0;
  Progress progress("info");
  RecordingVisitor v;
  v.on_progress = [&](double f) { progress.Update(f); };
  v.on_metadata = [&](const mcap::Metadata& m) { meta.push_back(m); };
  std::uint64_t foreign_messages = 0;
  v.on_foreign = [&](const mcap::Channel& c, const mcap::Schema* schema, const mcap::Message& m) {
    ++messages;
    ++foreign_messages;
    if (first == 0 || m.log_time < first) first = m.log_time;
    last = std::max(last, m.log_time);
    ChannelStats& cs = channels[c.topic + " #" + std::to_string(c.id)];
    if (cs.messages == 0) {
      cs.first = m.log_time;
      cs.note = "not a vdyn channel: " +
                (schema == nullptr
                     ? std::string("no schema")
                     : "schema '" + schema->name + "' (" +
                           (schema->encoding.empty() ? "no encoding" : schema->encoding) + ")") +
                ", messages " + (c.message_encoding.empty() ? "unencoded" : c.message_encoding);
    }
    ++cs.messages;
    cs.bytes += m.data.size();
    cs.last = std::max(cs.last, m.log_time);
  };
  std::uint64_t unchecked_states = 0;
  v.on_message = [&](const RecordedMessage& m) {
    ++messages;
    if (first == 0 || m.log_time < first) first = m.log_time;
    last = std::max(last, m.log_time);
    ChannelStats& c = channels[ChannelTopic(m.topic, m.key) + (m.repeat ? " (copies)" : "")];
    if (c.messages == 0) c.first = m.log_time;
    ++c.messages;
    c.bytes += m.data.size();
    c.last = std::max(c.last, m.log_time);
    if (m.topic == TopicId::kState) {
      // The fields the gaps need, and a check that the payload is a state of this vehicle: a
      // foreign writer's garbage under our names must not become steps.
      const std::optional<StateFields> fields = ReadStateFields(m.data, m.key);
      if (!fields) {
        ++c.malformed;
        return;
      }
      const std::uint64_t step = fields->step, step_ns = fields->step_ns;
      unchecked_states += m.unchecked ? 1 : 0;
      VehicleStats& vs = Vehicle(m.key);
      if (!vs.any) {
        vs.any = true;
        vs.first_step = step;
        vs.step_ns = static_cast<std::int64_t>(step_ns);
      }
      vs.gaps.State(step);
      vs.max_step = std::max(vs.max_step, step);
      ++vs.states;
    } else if (m.topic == TopicId::kEvents) {
      pb::SessionEvent e;
      // A server's event names it and is keyed by its vehicle.
      if (!e.ParseFromArray(m.data.data(), static_cast<int>(m.data.size())) ||
          e.server_id().empty() || e.vehicle_id() != m.key) {
        ++c.malformed;
        return;
      }
      ServerEvents& s = servers[e.server_id()];
      s.sequences.insert(e.sequence());
      if (e.has_spawned()) {
        // Only a vehicle with states has steps to tell about (its first state starts them).
        if (const auto it = vehicles.find(e.vehicle_id()); it != vehicles.end())
          it->second.gaps.Spawned(e.step());
      }
      if (e.has_spawned() || e.has_checkpoint()) {
        s.terrain_hashes.insert(e.has_spawned() ? e.spawned().terrain_hash() : e.checkpoint().terrain_hash());
        s.start_step.try_emplace(e.vehicle_id(), e.step());
        if (e.has_spawned() && !e.spawned().branched_from().empty()) {
          s.branched_from[e.vehicle_id()] = e.spawned().branched_from();
        }
      }
    } else if (m.topic == TopicId::kWorld) {
      pb::WorldDescription w;
      if (!w.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) {
        ++c.malformed;
        return;
      }
      std::size_t triangles = 0;
      for (const pb::Mesh& mesh : w.meshes()) triangles += static_cast<std::size_t>(mesh.indices_size() / 3);
      w.mutable_landmarks()->Clear();
      w.clear_meshes();
      w.add_meshes()->set_name(std::to_string(triangles));  // keeps the count, not the data
      worlds[w.server_id()] = std::move(w);
    }
  };
  const mcap::ScanResult scan = ScanRecording(reader, v);
  for (auto& [id, s] : servers) {
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
  for (const mcap::ChunkIndex& c : reader.Chunks()) {
    ++compression_chunks[c.compression.empty() ? "none" : c.compression];
    packed += c.compressed_size;
    unpacked += c.uncompressed_size;
  }
  progress.Finish();

  char line[512];
  auto t = [&](std::uint64_t ns) { return first == 0 ? 0.0 : static_cast<double>(ns - first) * 1e-9; };
  std::string comp;
  for (const auto& [name, n] : compression_chunks) comp += (comp.empty() ? "" : ", ") + std::to_string(n) + " " + name;
  const std::string foreign = foreign_messages == 0 ? std::string()
                                                    : ", " + std::to_string(foreign_messages) +
                                                          " of them not vdyn messages";
  std::snprintf(
      line, sizeof line,
      "file        %s (%s; %llu messages%s; chunks: %s; %.0f%% of the raw size)\n",
      path.string().c_str(), FormatBytes(static_cast<double>(reader.size())).c_str(),
      static_cast<unsigned long long>(messages), foreign.c_str(),
      comp.empty() ? "none" : comp.c_str(),
      unpacked > 0 ? 100.0 * static_cast<double>(packed) / static_cast<double>(unpacked) : 100.0);
  out << line;
  const std::string library = reader.header_library();
  out << "written by  " << (library.empty() ? "(not named in its header)" : library)
      << (scan.summary ? ", closed with index and summary\n"
                       : ", closed without a summary (no index: every reader must scan it)\n");
  // What the CRCs cover: a chunk whose CRC is 0 is checked only by the data section's CRC.
  const bool data_crc = scan.data_crc == mcap::ScanResult::DataCrc::kMatched;
  if (scan.chunks_unchecked == 0) {
    out << "integrity   every chunk's CRC checked"
        << (data_crc ? ", and the data section's\n" : "; the data section has no CRC\n");
  } else if (data_crc) {
    out << "integrity   " << scan.chunks_unchecked << " of " << scan.chunks
        << " chunks carry no CRC of their own; the data section's CRC covers them (checked)\n";
  } else {
    out << "integrity   UNCHECKED: " << scan.chunks_unchecked << " of " << scan.chunks
        << " chunks (" << scan.messages_unchecked
        << " messages) carry no CRC and the data section has none: "
        << "nothing checked their bytes\n";
  }
  for (const mcap::Metadata& m : meta) {
    if (m.name == "vdyn.recording") {
      auto get = [&](const char* k) { auto it = m.values.find(k); return it == m.values.end() ? std::string() : it->second; };
      out << "recorded    " << get("started_utc") << " on domain " << get("domain") << " (host " << get("host") << ")"
          << (get("part").empty() ? "" : ", part " + get("part") + " after " + get("previous_part")) << "\n";
      out << "command     " << get("command_line") << "\n";
      if (get("vehicles") != "all" || get("topics").find("vdyn/diagnostics") == std::string::npos) {
        out << "filters     topics " << get("topics") << "; vehicles " << get("vehicles") << "\n";
      }
      if (!get("branched_from").empty()) out << "branched    from " << get("branched_from") << "\n";
    }
  }
  std::snprintf(line, sizeof line, "time        %s (log time %s .. %s)\n", FormatDuration(t(last)).c_str(),
                first ? FormatUtc(first).c_str() : "-", last ? FormatUtc(last).c_str() : "-");
  out << line;
  for (const auto& [server, w] : worlds) {
    std::snprintf(line, sizeof line, "world       '%s' of server '%s': terrain hash %s, %d meshes, %s triangles, step %g ms\n",
                  w.name().c_str(), server.c_str(), Hex(w.terrain_hash()).c_str(), w.meshes_size(),
                  w.meshes(0).name().c_str(), static_cast<double>(w.step_ns()) * 1e-6);
    out << line;
  }
  if (worlds.empty()) out << "world       none recorded\n";
  out << "vehicles    " << (vehicles.empty() ? "no states recorded" : "") << "\n";
  for (const auto& [id, vs] : vehicles) {
    const double h = static_cast<double>(vs.step_ns) * 1e-9;
    std::snprintf(
        line, sizeof line,
        "  %-9u steps %llu..%llu (%.3f .. %.3f s of simulation), %llu states, %llu missing%s\n", id,
        static_cast<unsigned long long>(vs.first_step),
        static_cast<unsigned long long>(vs.max_step), static_cast<double>(vs.first_step) * h,
        static_cast<double>(vs.max_step + 1) * h, static_cast<unsigned long long>(vs.states),
        static_cast<unsigned long long>(vs.gaps.missing()),
        vs.gaps.jumps()
            ? (" (" + std::to_string(vs.gaps.jumps()) + " jumps: restarts or restores)").c_str()
            : "");
    out << line;
  }
  out << "channels\n";
  for (const auto& [name, c] : channels) {
    char rate[32] = "        -   ";
    if (RateMeaningful(c)) {
      std::snprintf(
          rate, sizeof rate, "%9.1f Hz",
          static_cast<double>(c.messages - 1) / (static_cast<double>(c.last - c.first) * 1e-9));
    }
    std::snprintf(line, sizeof line, "  %-30s %9llu msgs %s %10s   %8.3f .. %8.3f s", name.c_str(),
                  static_cast<unsigned long long>(c.messages), rate,
                  FormatBytes(static_cast<double>(c.bytes)).c_str(), t(c.first), t(c.last));
    out << line;
    if (c.malformed > 0) out << "  (" << c.malformed << " do not parse as the topic's type)";
    if (!c.note.empty()) out << "  (" << c.note << ")";
    out << "\n";
  }
  // Gaps: states and events that never reached the recorder, and what it counted itself.
  std::string gaps;
  for (const auto& [id, vs] : vehicles) {
    if (vs.gaps.missing() == 0) continue;
    gaps += "\n  vehicle " + std::to_string(id) + ": " + std::to_string(vs.gaps.missing()) +
            " states missing (largest gap " + std::to_string(vs.gaps.largest()) +
            " steps, from step " + std::to_string(vs.gaps.largest_from()) + ")";
  }
  for (const auto& [server, s] : servers) {
    if (s.missing == 0) continue;
    gaps += "\n  server '" + server + "': " + std::to_string(s.missing) + " events missing in " +
            std::to_string(s.gaps) + " gaps";
  }
  for (const mcap::Metadata& m : meta) {
    if (m.name != "vdyn.recording.end") continue;
    for (const auto& [k, val] : m.values) {
      const bool loss = k.ends_with(".lost") || k.ends_with(".dropped") || k.ends_with(".malformed");
      if (loss && val != "0") gaps += "\n  the recorder counted " + val + " " + k.substr(k.rfind('.') + 1) + " on " + k.substr(0, k.rfind('.'));
    }
  }
  for (const auto& [name, c] : channels) {
    if (c.malformed == 0) continue;
    gaps += "\n  " + name + ": " + std::to_string(c.malformed) + " of " +
            std::to_string(c.messages) +
            " messages do not parse as the topic's type: left out of the counts above";
  }
  out << "gaps" << (gaps.empty() ? "        none" : gaps) << "\n";
  PrintRecovered(meta, first, out);
  for (const std::string& note : IntegrityNotes({}, scan, unchecked_states, "states")) {
    out << "            " << note << "\n";
  }
  for (const auto& [server, s] : servers) {
    std::snprintf(line, sizeof line, "events      server '%s': %llu events, sequence %llu..%llu%s\n", server.c_str(),
                  static_cast<unsigned long long>(s.count), static_cast<unsigned long long>(s.first),
                  static_cast<unsigned long long>(s.last), s.gaps ? "" : ", no gap");
    out << line;
    for (const auto& [veh, from] : s.branched_from) {
      out << "            vehicle " << veh << " continues " << from << "\n";
    }
  }
  // Re-simulation: the world it ran on, a start for each vehicle, no lost event.
  std::string no;
  std::uint64_t event_messages = 0, bad_events = 0;
  for (const auto& [name, c] : channels) {
    if (c.note.empty() && name.rfind(transport::Spec(TopicId::kEvents).name, 0) == 0) {
      event_messages += c.messages;
      bad_events += c.malformed;
    }
  }
  std::string named;  // channels named like our events that hold something else
  for (const auto& [name, c] : channels) {
    if (!c.note.empty() && name.rfind(transport::Spec(TopicId::kEvents).name, 0) == 0) {
      named += (named.empty() ? "" : ", ") + name.substr(0, name.find(" #"));
    }
  }
  if (servers.empty()) {
    no = event_messages > 0 ? "the " + std::to_string(bad_events) +
                                  " messages on vdyn/events do not parse as session events"
         : !named.empty()
             ? "no session events: " + named + " holds another type (not a vdyn channel)"
             : "no session events recorded (vdyn/events)";
  }
  std::string partly;  // what verify cannot cover: it re-simulates around it
  for (const auto& [server, s] : servers) {
    if (!no.empty()) break;
    const auto w = worlds.find(server);
    if (w == worlds.end()) {
      no = "no world description of server '" + server + "' (vdyn/world)";
    } else if (s.terrain_hashes.size() > 1 || (s.terrain_hashes.size() == 1 && *s.terrain_hashes.begin() != w->second.terrain_hash())) {
      no = "the events name another terrain than the recorded world";
    } else if (s.gaps > 0) {
      partly += "; " + std::to_string(s.missing) + " events of server '" + server +
                "' are missing (" + std::to_string(s.gaps) + " gaps)";
    }
  }
  std::string starts;
  for (const auto& [id, vs] : vehicles) {
    std::optional<std::uint64_t> start;
    for (const auto& [server, s] : servers) {
      if (auto it = s.start_step.find(id); it != s.start_step.end()) start = it->second;
    }
    if (!start) {
      if (no.empty()) no = "vehicle " + std::to_string(id) + " has no spawn or checkpoint event";
    } else {
      starts += (starts.empty() ? "" : ", ") + std::string("vehicle ") + std::to_string(id) + " from step " + std::to_string(*start);
    }
  }
  if (!no.empty()) {
    out << "re-simulates no: " << no << "\n";
  } else if (!partly.empty()) {
    out << "re-simulates in parts: "
        << (starts.empty() ? std::string("no states to check") : starts) << partly
        << ": `vdyn-recorder verify` re-simulates up to each gap and again from the next "
           "checkpoint "
           "after it, and says which steps it could not verify\n";
  } else {
    out << "re-simulates yes: " << (starts.empty() ? std::string("no states to check") : starts)
        << " (`vdyn-recorder verify` checks every state hash)\n";
  }
  return 0;
}

}  // namespace vdyn::recorder
